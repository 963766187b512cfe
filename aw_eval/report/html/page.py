"""Assembles ``report.html`` and its folder ``report_files/``:

- ``report.css``, ``report.js`` (sortable tables), ``viewer.js`` (3D view), plotly's offline
  bundle ``plotly-<version>.min.js`` (written once, loaded only when a 3D view opens);
- ``renders/``: card pictures and filmstrip frames, named by content hash and reused;
- ``viewer/``: one script per task with the 3D view's data, loaded when its view opens.

Files in ``renders/`` and ``viewer/`` that the new page no longer uses are removed.
"""

from __future__ import annotations

import hashlib
import html
import os
import re
import time
from collections.abc import Callable
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import orjson

from aw.formats import FormatError
from aw.render_platform import RenderError
from aw_eval.report.fmt import fixed
from aw_eval.report.html.cards import Picture, TaskRuns, load_run_view, system_colors, task_card, viewer_data
from aw_eval.report.html.markup import markdown_to_html, scroll_box, slug
from aw_eval.report.html.scenes import TaskScene
from aw_eval.report.markdown import SUMMARY_SECTIONS, TABLE1, system_label
from aw_eval.report.results import protocol_of
from aw_eval.study.table import Study

__all__ = ["write_html", "build_card", "CardJob", "CardResult", "HtmlStats", "ASSETS_DIR"]

ASSETS_DIR = "report_files"
MIN_POOL_TASKS = 4  # fewer tasks: cards are built in this process whatever ``jobs`` says
GLANCE_TASKS = 6  # tasks in the strip of pictures near the top (the first of each source)
GLANCE_SIZE = (160, 120)  # its pictures: the cards' renders, shown smaller
_STATIC = ("report.css", "report.js", "viewer.js")


@dataclass
class HtmlStats:
    path: Path
    html_bytes: int
    files_bytes: int
    renders: int
    renders_new: int
    seconds: float


def _plotly_bundle(folder: Path) -> str:
    """Write plotly's offline bundle once; returns its file name."""
    import plotly
    from plotly.offline import get_plotlyjs

    name = f"plotly-{plotly.__version__}.min.js"
    path = folder / name
    if not path.is_file():
        tmp = path.with_name(name + f".tmp{os.getpid()}")
        tmp.write_text(get_plotlyjs(), encoding="utf-8")
        tmp.replace(path)
    for old in folder.glob("plotly-*.min.js"):
        if old.name != name:
            old.unlink()
    return name


def _copy_static(folder: Path) -> None:
    pkg = resources.files("aw_eval.report.html") / "assets"
    for name in _STATIC:
        data = (pkg / name).read_bytes()
        path = folder / name
        if not path.is_file() or path.read_bytes() != data:
            path.write_bytes(data)


def _overview(doc: dict[str, Any], study: Study) -> str:
    """A sortable table of every task: PA/SR per system, linking to the cards."""
    runs = {(r["system"], r["task_id"]): r for r in doc["runs"]}
    head = '<th>Task</th><th>Source</th><th>Condition</th><th>Variant</th><th class="r">Parts</th>' + "".join(
        f'<th class="r">{html.escape(s)} PA (%)</th><th class="r">SR</th>' for s in study.systems
    )
    rows = []
    for t in doc["tasks"]:
        tid = t["task_id"]
        tds = (
            f'<td class="l"><a href="#task-{slug(tid)}">{html.escape(tid)}</a></td><td class="l">{html.escape(t["source"])}'
            f'</td><td class="l">{html.escape(t["condition"])}</td><td class="l">{html.escape(t["variant"])}</td>'
            f'<td class="r" data-v="{t["n_parts"]}">{t["n_parts"]}</td>'
        )
        for s in study.systems:
            r = runs[(s, tid)]
            if r["status"] == "scored":
                tds += f'<td class="r" data-v="{r["pa"]:.6g}">{fixed(r["pa"])}</td><td class="r" data-v="{r["sr"]:g}">{int(r["sr"])}</td>'
            else:
                tds += f'<td class="r" data-v="">{html.escape(r["status"])}</td><td class="r" data-v=""></td>'
        rows.append(f"<tr>{tds}</tr>")
    return scroll_box(
        f'<table class="sortable tasks"><thead><tr>{head}</tr></thead><tbody>{"".join(rows)}</tbody></table>'
    )


def _toc(body: str) -> str:
    links = [f'<a href="#{m.group(1)}">{m.group(2)}</a>' for m in re.finditer(r'<h2 id="([^"]+)">(.*?)</h2>', body)]
    return "<nav><b>Contents</b>" + "".join(links) + "</nav>"


GLANCE_TITLE = "At a glance"


def _glance(doc: dict[str, Any], systems: list[str], pictures: dict[str, list[Picture]]) -> str:
    """The first task of each source with a picture of a run (at most :data:`GLANCE_TASKS`): the
    target beside every system's final state, small, linking to the task's card; empty when no
    card has pictures of runs."""
    picked, sources = [], set()
    for t in doc["tasks"]:
        pics = pictures.get(t["task_id"]) or []
        if t["variant"] == "original" and t["source"] not in sources and any(p.src and not p.target for p in pics):
            sources.add(t["source"])
            picked.append((t, pics))
    if not picked:
        return ""
    w, h = GLANCE_SIZE
    head = "<th>Task</th><th>Target</th>" + "".join(f"<th>{html.escape(system_label(doc, s))}</th>" for s in systems)
    rows = []
    for t, pics in picked[:GLANCE_TASKS]:
        tid = t["task_id"]
        tds = (
            f'<td class="l"><a href="#task-{slug(tid)}">{html.escape(tid)}</a><br><span class="note">'
            f"{t['n_parts']} parts</span></td>"
        )
        for p in pics:
            img = (
                f'<img src="{html.escape(p.src)}" alt="{html.escape(p.label)} on {html.escape(tid)}" width="{w}" '
                f'height="{h}">'
                if p.src
                else ""
            )
            tds += f'<td>{img}<div class="note">{html.escape(p.numbers)}</div></td>'
        rows.append(f"<tr>{tds}</tr>")
    return (
        f'<h2 id="{slug(GLANCE_TITLE)}">{GLANCE_TITLE}</h2><p>The first task of each source: the target beside '
        "every system's final state (registered onto the target, one camera per task). Each task has a card "
        'under <a href="#tasks">Tasks</a>.</p>'
        + scroll_box(f'<table class="glance"><thead><tr>{head}</tr></thead><tbody>{"".join(rows)}</tbody></table>')
    )


def _arrange(body: str, glance: str) -> str:
    """The page's sections in order: the summary sections open, the glance strip after Table 1,
    every other section folded (its heading stays visible, so the contents' links still land)."""
    chunks = re.split(r'(?=<h2 id=")', body)
    open_ids = {slug(t) for t in SUMMARY_SECTIONS}
    out, placed = [], not glance
    for chunk in chunks:
        m = re.match(r'<h2 id="([^"]+)">(.*?)</h2>', chunk)
        if m is None or m.group(1) in open_ids:
            out.append(chunk)
        else:
            out.append(f'<details class="fold"><summary>{m.group(0)}</summary>{chunk[m.end() :]}</details>')
        if m is not None and m.group(1) == slug(TABLE1) and not placed:
            out.append(glance)
            placed = True
    if not placed:  # no Table 1 (a suite of variants only): the strip goes first
        out.insert(1, glance)
    return "".join(out)


@dataclass(frozen=True)
class CardJob:
    """Everything one task's card needs; picklable, so cards are built in worker processes."""

    task: dict[str, Any]
    runs: TaskRuns
    doc_runs: dict[tuple[str, str], dict[str, Any]]
    suite_dir: str | None
    files: str
    colors: dict[str, str]
    threshold: float  # the protocol's part-correct threshold
    viewer_url: str | None = None  # an aw-view of the same runs: each run links to its episode page


@dataclass
class CardResult:
    html: str
    viewer_file: str | None
    render_files: list[str]
    no_render: str | None  # why the card has no pictures, when rendering failed
    pictures: list[Picture]  # the card's first row: target and final states


def build_card(job: CardJob) -> CardResult:
    """One task's card: its pictures rendered (or reused) and its data file written."""
    tid = job.task["task_id"]
    files, rel = Path(job.files), f"{ASSETS_DIR}/renders/"
    scene, views, viewer_src, viewer_file, no_render = None, {}, None, None, None
    facts = job.runs.facts.get(tid)
    if job.suite_dir is not None and facts is not None:
        try:
            scene = TaskScene.load(Path(job.suite_dir), tid, list(facts.part_ids), facts.divisor)
        except (FormatError, OSError, ValueError, KeyError):
            scene = None
    try:
        if scene is not None:
            for s in job.runs.systems:
                v = load_run_view(job.runs, s, tid, scene)
                if v is not None:
                    views[s] = v
            if views:
                vd = orjson.dumps(viewer_data(scene, views), option=orjson.OPT_SERIALIZE_NUMPY)
                viewer_file = f"{slug(tid)[:60]}-{hashlib.sha1(vd).hexdigest()[:12]}.js"
                path = files / "viewer" / viewer_file
                if not path.is_file():
                    path.write_bytes(b"AWViewer.register(" + orjson.dumps(tid) + b"," + vd + b");\n")
                viewer_src = f"{ASSETS_DIR}/viewer/{viewer_file}"
        card = None
        if scene is not None:
            try:
                card = task_card(
                    job.runs,
                    job.task,
                    job.doc_runs,
                    scene,
                    views,
                    files / "renders",
                    rel,
                    viewer_src,
                    job.colors,
                    threshold=job.threshold,
                    viewer_url=job.viewer_url,
                )
            except RenderError as exc:
                no_render = f"No pictures: offscreen rendering is unavailable ({exc})."
        if card is None:
            card = task_card(
                job.runs,
                job.task,
                job.doc_runs,
                None,
                views,
                files / "renders",
                rel,
                viewer_src,
                job.colors,
                **({"no_pictures": no_render} if no_render else {}),
                viewer_url=job.viewer_url,
            )
    finally:
        if scene is not None:
            scene.close()
    return CardResult(
        card.html, viewer_file, [p.split("/")[-1] for p in _srcs(card.html, rel)], no_render, card.pictures
    )


def _cards(jobs: list[CardJob], n_jobs: int):
    """Build the cards in order, in ``n_jobs`` worker processes (spawned: each opens its own GL
    contexts) or in this process."""
    if n_jobs <= 1 or len(jobs) <= 1:
        yield from map(build_card, jobs)
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(max_workers=min(n_jobs, len(jobs)), mp_context=multiprocessing.get_context("spawn")) as ex:
        yield from ex.map(build_card, jobs)


def write_html(
    study: Study,
    doc: dict[str, Any],
    markdown: str,
    out_dir: str | Path,
    suite_dir: str | Path | None,
    log: Callable[[str], None] | None = None,
    jobs: int = 1,
    viewer_url: str | None = None,
) -> HtmlStats:
    """Write ``out_dir/report.html`` and ``out_dir/report_files/``; ``markdown`` is report.md's text
    (its image links are relative to ``out_dir``). Cards are built in ``jobs`` processes. Tasks
    whose meshes cannot be read (no ``suite_dir``, official packages) get cards without pictures.
    ``viewer_url``: an ``aw-view`` of the same runs folder; each run links to its episode page."""
    t0 = time.perf_counter()
    out = Path(out_dir)
    files = out / ASSETS_DIR
    renders, viewer = files / "renders", files / "viewer"
    for d in (files, renders, viewer):
        d.mkdir(parents=True, exist_ok=True)
    _copy_static(files)
    plotly_name = _plotly_bundle(files)
    before = {p.name for p in renders.iterdir()}
    colors = system_colors(list(study.systems))
    doc_runs = {(r["system"], r["task_id"]): r for r in doc["runs"]}
    card_jobs = [
        CardJob(
            t,
            TaskRuns.of(study, t["task_id"]),
            {(s, t["task_id"]): doc_runs[(s, t["task_id"])] for s in study.systems},
            None if suite_dir is None else str(suite_dir),
            str(files),
            colors,
            protocol_of(doc).threshold,
            viewer_url,
        )
        for t in doc["tasks"]
    ]
    used_renders: set[str] = set()
    used_viewer: set[str] = set()
    cards, pictures, no_render = [], {}, None
    # spawned workers take seconds to start: not worth it for a handful of cards
    for job, res in zip(card_jobs, _cards(card_jobs, jobs if len(card_jobs) >= MIN_POOL_TASKS else 1), strict=True):
        cards.append(res.html)
        pictures[job.task["task_id"]] = res.pictures
        used_renders.update(res.render_files)
        if res.viewer_file:
            used_viewer.add(res.viewer_file)
        if res.no_render and no_render is None:
            no_render = res.no_render
            if log is not None:
                log(f"report.html without pictures: {res.no_render}")
    for folder, used in ((renders, used_renders), (viewer, used_viewer)):
        for p in folder.iterdir():
            if p.name not in used:
                p.unlink()
    body = _arrange(markdown_to_html(markdown), _glance(doc, list(study.systems), pictures))
    body += (
        '\n<h2 id="tasks">Tasks</h2><p>Every task with each system\'s final PA and SR; the cards below show '
        "the target beside each system's final state (registered onto the target, one camera, part colours "
        "shared), filmstrips at the quality curves' normalized times, per-run curves and tool calls, and a 3D "
        "view of the recorded states.</p>" + _overview(doc, study) + "".join(cards)
    )
    title = html.escape(f"AssemblyWorld scores: {doc['suite']['name']}")
    page = (
        f'<!doctype html>\n<html lang="en"><head><meta charset="utf-8"><title>{title}</title>'
        f'<meta name="viewport" content="width=device-width, initial-scale=1">'
        f'<link rel="stylesheet" href="{ASSETS_DIR}/report.css"></head><body>{_toc(body)}<main>{body}</main>'
        f'<script src="{ASSETS_DIR}/report.js"></script>'
        f'<script src="{ASSETS_DIR}/viewer.js" data-plotly="{ASSETS_DIR}/{plotly_name}"></script></body></html>\n'
    )
    path = out / "report.html"
    tmp = path.with_name(f"report.html.tmp{os.getpid()}")
    tmp.write_text(page, encoding="utf-8")
    tmp.replace(path)
    files_bytes = sum(p.stat().st_size for p in files.rglob("*") if p.is_file())
    new = len(used_renders - before)
    stats = HtmlStats(path, path.stat().st_size, files_bytes, len(used_renders), new, time.perf_counter() - t0)
    if log is not None:
        log(
            f"report.html: {stats.html_bytes / 1e6:.1f} MB page, {files_bytes / 1e6:.1f} MB in {ASSETS_DIR}/, "
            f"{stats.renders} pictures ({new} rendered now), {stats.seconds:.1f} s"
        )
    return stats


def _srcs(text: str, prefix: str) -> list[str]:
    return re.findall(r'src="(' + re.escape(prefix) + r'[^"]+)"', text)
