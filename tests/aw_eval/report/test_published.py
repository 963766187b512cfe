"""The paper's eight systems in aw-score's tables: the data file holds the paper's Table 1 and
Table A-3 (read from the paper's LaTeX when it is at hand), the rows appear only on the official
benchmark (by its package's identity), marked and never bold, and elsewhere one line says why."""

from __future__ import annotations

import json
import re
from pathlib import Path

import orjson
import pytest

from aw.official.convert import convert, official_benchmark_problem, package_record_path
from aw.official.package import BENCHMARK_SHA256, EXPECTED_SAMPLES, OfficialPackage, file_sha256
from aw_eval.cli import main as aw_score
from aw_eval.report.published import MARK, load_published
from tests.aw.official.builders import FINAL, write_active, write_package

PAPER = Path(__file__).resolve().parents[3].parent / "shared" / "spec" / "assemblyworld-paper.tex"


def _paper_rows(tex: str, label: str) -> list[list[str]]:
    """The body rows of the table labelled ``label``: cells without LaTeX bold."""
    body = tex[tex.index(f"\\label{{{label}}}") :]
    body = body[body.index("\\midrule") : body.index("\\bottomrule")]
    rows = []
    for line in body.splitlines():
        if line.strip().endswith("\\\\"):
            rows.append([re.sub(r"\\textbf\{(.*?)\}", r"\1", c).strip() for c in line.strip()[:-2].split("&")])
    return rows


def _interval(text: str) -> list[float]:
    return [float(x) for x in text.strip("[]").split(",")]


@pytest.mark.skipif(not PAPER.is_file(), reason=f"the paper's LaTeX is not at hand ({PAPER}; a fresh clone lacks it)")
def test_the_data_file_holds_the_papers_table_1_and_table_a3():
    tex = PAPER.read_text(encoding="utf-8")
    data = load_published()
    assert "Table 1" in data["source"] and "Table A-3" in data["source"]
    table1 = _paper_rows(tex, "tab:benchmark")
    overview = {r[0]: r for r in _paper_rows(tex, "tab:analysis_overview")}
    assert [s["system"] for s in data["systems"]] == [r[0] for r in table1]
    for s, row in zip(data["systems"], table1, strict=True):
        nums = [float(x) for x in row[2:]]
        assert s["harness"] == row[1]
        assert s["sr_cells"] == nums[:5] and s["sr"] == nums[5]
        assert [s["time_min"], s["mcp_calls"], s["tokens_m"], s["cost_usd"]] == nums[6:]
        a3 = overview[s["name_in_table_a3"]]
        assert [s["sr"], s["sr_ci"], s["pa"], s["pa_ci"], s["errors_timeouts"]] == [
            float(a3[1]),
            _interval(a3[2]),
            float(a3[3]),
            _interval(a3[4]),
            int(a3[5]),
        ]
    assert len(overview) == len(data["systems"]) == 8


@pytest.fixture(scope="module")
def converted(tmp_path_factory) -> tuple[Path, Path, Path]:
    """A suite and runs converted from a small official-layout package (two samples)."""
    root = tmp_path_factory.mktemp("published")
    pkg = OfficialPackage(write_package(root / "benchmark", {"partnet-none": ["21905", "743"]}), strict=False)
    logs = root / "logs" / "run-1" / "blocks" / "partnet-none" / "samples"
    for sid in ("21905", "743"):
        write_active(pkg.initial_archive("partnet-none", sid), logs / sid / "final.episode.zip", final=FINAL)
    convert(pkg.root, root / "logs", root / "suite", root / "runs")
    return pkg.root, root / "suite", root / "runs"


def test_a_converted_suite_records_its_packages_identity(converted):
    package, suite, _ = converted
    record = json.loads(package_record_path(suite).read_text())
    assert record["benchmark_sha256"] == file_sha256(package / "benchmark.json") and record["samples"] == 2
    assert "is not the official benchmark's" in official_benchmark_problem(suite)
    assert "not converted from the official benchmark package" in official_benchmark_problem(package.parent)


def _report(suite: Path, runs: Path, out: Path) -> tuple[dict, str]:
    args = [str(suite), str(runs), "--out", str(out), "--jobs", "1", "--final-only", "--final", "fast"]
    assert (
        aw_score(args + ["--no-plots", "--no-html", "--bootstrap", "20", "--permutations", "20", "--no-progress"]) == 0
    )
    return json.loads((out / "scores.json").read_text()), (out / "report.md").read_text()


def _section(md: str, title: str) -> str:
    return md.split(f"## {title}", 1)[1].split("\n## ", 1)[0]


def test_published_rows_only_on_the_official_benchmark_marked_and_never_bold(converted, tmp_path):
    _, suite, runs = converted
    doc, md = _report(suite, runs, tmp_path / "other")
    assert doc["published"]["shown"] is False and not doc["published"]["systems"]
    assert MARK not in md
    assert "The paper's eight systems are not shown" in _section(md, "Table 1: benchmark results")
    assert "is not the official benchmark's" in _section(md, "Table 1: benchmark results")

    # the record a conversion of the official package writes: its pinned digest, its 100 samples
    record = orjson.loads(package_record_path(suite).read_bytes())
    record.update(benchmark_sha256=BENCHMARK_SHA256, samples=EXPECTED_SAMPLES)
    package_record_path(suite).write_bytes(orjson.dumps(record))
    assert official_benchmark_problem(suite) is None
    doc, md = _report(suite, runs, tmp_path / "official")
    assert doc["published"]["shown"] is True
    table1, overview = _section(md, "Table 1: benchmark results"), _section(md, "Table A-3: benchmark quality")
    for s in load_published()["systems"]:
        row1 = next(line for line in table1.splitlines() if line.startswith(f"| {s['system']} ("))
        assert MARK in row1 and "**" not in row1
        cells = [c.strip() for c in row1.strip("|").split("|")]
        # this suite has one cell, PartNet NR: the paper's first; then Overall SR and the resources
        assert cells[1:] == [f"{s['sr_cells'][0]:.2f}", f"{s['sr']:.2f}", f"{s['time_min']:.2f}", str(s["mcp_calls"]),
                             f"{s['tokens_m']:.2f}", f"{s['cost_usd']:.2f}"]  # fmt: skip
        row3 = next(line for line in overview.splitlines() if line.startswith(f"| {s['system']} ("))
        assert MARK in row3 and "**" not in row3 and row3.rstrip(" |").endswith(str(s["errors_timeouts"]))
    assert "Rows marked 'published, not rescored'" in table1
    assert MARK not in _section(md, "Table A-4: paired system differences")  # no per-task data: no paired test
