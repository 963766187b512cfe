"""Outputs of ``aw-score``: ``scores.json``, ``tasks.csv``, ``checkpoints.csv``, ``report.md``,
PNG plots and ``report.html`` (with its folder ``report_files/``), all written into the output
directory."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import orjson

from aw.formats.io import write_bytes_atomic
from aw_eval.report.csvs import write_checkpoint_csv, write_task_csv
from aw_eval.report.markdown import render_markdown
from aw_eval.report.plots import write_plots
from aw_eval.report.results import SCHEMA, SCHEMA_VERSION, AnalysisSettings, build_results
from aw_eval.study.table import Study

__all__ = [
    "SCHEMA",
    "SCHEMA_VERSION",
    "AnalysisSettings",
    "build_results",
    "render_markdown",
    "write_plots",
    "write_outputs",
    "write_json",
]


def write_json(path: Path, doc: Any) -> None:
    data = orjson.dumps(doc, option=orjson.OPT_INDENT_2 | orjson.OPT_SERIALIZE_NUMPY | orjson.OPT_NON_STR_KEYS)
    write_bytes_atomic(path, data + b"\n")  # a full disk leaves no partial file and names this one


def _refinement(suite_dir: str, runs_dir: str) -> dict[str, Any] | None:
    if not (suite_dir and runs_dir):
        return None
    from aw_eval.analyses.refinement import refinement_study

    return refinement_study(suite_dir, runs_dir)


def write_outputs(
    study: Study,
    out_dir: str | Path,
    settings: AnalysisSettings,
    *,
    suite_dir: str = "",
    runs_dir: str = "",
    score_stats: dict[str, Any] | None = None,
    plots: bool = True,
    html: bool = True,
    log: Callable[[str], None] | None = None,
    jobs: int = 1,
    viewer_url: str | None = None,
) -> dict[str, Any]:
    """Write every output; returns ``{"doc": scores document, "files": {name: path}}``. ``jobs``:
    processes that build report.html's cards; ``viewer_url``: an ``aw-view`` of the same runs,
    which report.html links each run to."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    doc = build_results(study, settings, suite_dir=suite_dir, runs_dir=runs_dir, score_stats=score_stats)
    refinement = _refinement(suite_dir, runs_dir)  # only when RUNS/refinement_study.json exists
    if refinement is not None:
        doc["refinement"] = refinement
    files = {
        "scores": out / "scores.json",
        "tasks_csv": out / "tasks.csv",
        "checkpoints_csv": out / "checkpoints.csv",
        "report": out / "report.md",
    }
    write_task_csv(study, files["tasks_csv"])
    write_checkpoint_csv(study, files["checkpoints_csv"])
    made = write_plots(doc, out / "plots") if plots else {}
    if refinement is not None and plots:
        from aw_eval.report.refinement import write_refinement_plot

        name = write_refinement_plot(refinement, out / "plots")
        if name:
            made["refinement_paired_cd"] = name
    doc["plots"] = {k: f"plots/{v}" for k, v in made.items()}
    write_json(files["scores"], doc)
    markdown = render_markdown(doc, doc["plots"])
    if refinement is not None:
        from aw_eval.report.refinement import render_refinement

        markdown += "\n" + render_refinement(refinement, doc["plots"].get("refinement_paired_cd"))
    files["report"].write_text(markdown)
    if html:
        from aw_eval.report.html import write_html  # imports plotly only when asked

        files["html"] = write_html(
            study, doc, markdown, out, suite_dir or None, log=log, jobs=jobs, viewer_url=viewer_url
        ).path
    for k, v in made.items():
        files[f"plot_{k}"] = out / "plots" / v
    return {"doc": doc, "files": files}
