"""``aw-score`` on a suite and runs converted from an official package and run log
(``aw-prepare official``): the exported episodes count as finished runs and score from the
official points (the final archive that reaches the targets has SR 1, PA 100)."""

from __future__ import annotations

import json

from aw.official.convert import convert
from aw.official.package import OfficialPackage
from aw_eval.cli import main
from tests.aw.official.builders import FINAL, write_active, write_package


def test_converted_official_runs_score_as_finished(tmp_path):
    pkg = OfficialPackage(write_package(tmp_path / "benchmark", {"partnet-none": ["21905", "743"]}), strict=False)
    logs = tmp_path / "logs" / "run-1" / "blocks" / "partnet-none" / "samples"
    write_active(pkg.initial_archive("partnet-none", "21905"), logs / "21905" / "final.episode.zip")
    wrong = FINAL.copy()
    wrong[2, :3] += [0.4, 0.0, 0.0]
    write_active(pkg.initial_archive("partnet-none", "743"), logs / "743" / "final.episode.zip", final=wrong)
    convert(pkg.root, tmp_path / "logs", tmp_path / "suite", tmp_path / "runs")
    assert (
        main(
            [
                str(tmp_path / "suite"),
                str(tmp_path / "runs"),
                "--out",
                str(tmp_path / "out"),
                "--jobs",
                "1",
                "--final-only",
                "--final",
                "fast",
                "--no-plots",
                "--bootstrap",
                "200",
                "--permutations",
                "200",
                "--no-progress",
            ]
        )
        == 0
    )
    runs = {r["task_id"]: r for r in json.loads((tmp_path / "out" / "scores.json").read_text())["runs"]}
    right, off = runs["partnet-none--21905"], runs["partnet-none--743"]
    assert right["status"] == off["status"] == "scored"
    assert right["sr"] == 1.0 and right["pa"] == 100.0
    assert off["sr"] == 0.0 and off["pa"] < 100.0
