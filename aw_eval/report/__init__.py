"""Outputs of ``aw-score``: ``scores.json``, ``tasks.csv``, ``checkpoints.csv``, ``report.md``,
PNG plots and ``report.html`` (with its folder ``report_files/``), all written into a staging
folder and then moved into the output directory together."""

from __future__ import annotations

import re
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import orjson

from aw import interrupts
from aw.formats.io import link_tree, publish_staged, staging_dir, write_bytes_atomic, write_text_atomic
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
    which report.html links each run to.

    Everything is written into a hidden staging folder first and moved into ``out_dir`` only when
    all of it is written, with signals deferred (:mod:`aw.interrupts`): an interrupt or a write
    error leaves the previous outputs as they were, byte for byte, and no temporary file (one a
    killed call left is removed by the next). A write error names the output file."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    stage = staging_dir(out, "report")
    try:
        result = _write_all(
            study, stage, out, settings, suite_dir, runs_dir, score_stats, plots, html, log, jobs, viewer_url
        )
        interrupts.check()  # an interrupt that a library swallowed: the previous outputs stay
        with interrupts.deferred():
            publish_staged(stage, out)
        for left in out.iterdir():  # temporary files an older version left beside its outputs
            if left.is_file() and _is_temporary(left.name):
                left.unlink(missing_ok=True)
    except OSError as exc:  # name the output, not its staged copy
        name = exc.filename and Path(exc.filename)
        if name and name.is_relative_to(stage):
            raise OSError(exc.errno, exc.strerror or str(exc), str(out / name.relative_to(stage))) from None
        raise
    finally:
        shutil.rmtree(stage, ignore_errors=True)
    result["files"] = {k: out / Path(v).relative_to(stage) for k, v in result["files"].items()}
    return result


def _is_temporary(name: str) -> bool:
    """A temporary file an interrupted or failed write left (``*.tmp<pid>*``)."""
    return re.search(r"\.tmp[0-9]", name) is not None


def _write_all(
    study: Study,
    out: Path,
    published: Path,
    settings: AnalysisSettings,
    suite_dir: str,
    runs_dir: str,
    score_stats: dict[str, Any] | None,
    plots: bool,
    html: bool,
    log: Callable[[str], None] | None,
    jobs: int,
    viewer_url: str | None,
) -> dict[str, Any]:
    """Every output written into the staging folder ``out`` (empty); ``published``: the output
    directory, whose report pictures are reused."""
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
    markdown = render_markdown(doc, doc["plots"])  # a refinement study's table comes first
    write_text_atomic(files["report"], markdown)
    if html:
        from aw_eval.report.html import ASSETS_DIR, write_html  # imports plotly only when asked

        if (published / ASSETS_DIR).is_dir():  # its pictures are reused: start from them, linked
            link_tree(published / ASSETS_DIR, out / ASSETS_DIR, skip=_is_temporary)
        files["html"] = write_html(
            study, doc, markdown, out, suite_dir or None, log=log, jobs=jobs, viewer_url=viewer_url
        ).path
    for k, v in made.items():
        files[f"plot_{k}"] = out / "plots" / v
    return {"doc": doc, "files": files}
