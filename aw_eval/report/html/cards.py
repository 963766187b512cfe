"""One card per task: the target beside every system's final state (one camera, shared part
colours), their scores and per-part errors, each run's filmstrip at the quality curves'
normalized checkpoints, its PA/SCD curve, its tool calls, and the data of the 3D viewer."""

from __future__ import annotations

import html
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import quote, urlsplit, urlunsplit

import numpy as np
import orjson

from aw.formats import FormatError, read_final, read_trajectory
from aw.meshes import display_parts
from aw_eval.analyses.curves import NORMALIZED_POINTS, normalized_states
from aw_eval.report.fmt import DASH, fixed
from aw_eval.report.html.markup import scroll_box, slug
from aw_eval.report.html.scenes import TaskScene, aligned_poses
from aw_eval.report.html.svg import Series, step_chart
from aw_eval.settings import ProtocolSettings
from aw_eval.study.episode import poses_array
from aw_eval.study.model import RunScore, TaskFacts
from aw_eval.study.table import RunRecord, Study

__all__ = [
    "TaskRuns",
    "RunView",
    "Picture",
    "Card",
    "load_run_view",
    "task_card",
    "registration_hint",
    "viewer_data",
    "system_colors",
    "episode_link",
    "CARD_SIZE",
    "FRAME_SIZE",
    "MAX_VIEWER_STATES",
    "MAX_LISTED_CALLS",
]

CARD_SIZE = (320, 240)  # target and final-state pictures
FRAME_SIZE = (160, 120)  # filmstrip frames
MAX_VIEWER_STATES = 200  # recorded states per run in the 3D viewer (evenly spaced; first and last kept)
MAX_LISTED_CALLS = 2000  # tool calls listed per run
_SYSTEM_PALETTE = (
    "#4C72B0",
    "#DD8452",
    "#55A868",
    "#C44E52",
    "#8172B3",
    "#937860",
    "#DA8BC3",
    "#8C8C8C",
    "#CCB974",
    "#64B5CD",
)


def episode_link(viewer_url: str, system: str, task_id: str) -> str:
    """The episode page of run ``RUNS/<system>/<task_id>`` in an ``aw-view`` of ``RUNS`` at
    ``viewer_url`` (the URL it printed; a token in its query is kept)."""
    url = urlsplit(viewer_url)
    path = url.path.rstrip("/") + "/episode/" + quote(f"{system}/{task_id}", safe="/")
    return urlunsplit((url.scheme, url.netloc, path, url.query, ""))


def system_colors(systems: list[str]) -> dict[str, str]:
    return {s: _SYSTEM_PALETTE[i % len(_SYSTEM_PALETTE)] for i, s in enumerate(systems)}


@dataclass
class TaskRuns:
    """One task's slice of a :class:`~aw_eval.study.table.Study` (what a card needs; small enough
    to send to a worker process): every system's run record and the task's facts."""

    systems: list[str]
    records: dict[tuple[str, str], RunRecord]
    facts: dict[str, TaskFacts]

    @classmethod
    def of(cls, study: Study, task_id: str) -> TaskRuns:
        facts = {task_id: study.facts[task_id]} if task_id in study.facts else {}
        return cls(list(study.systems), {(s, task_id): study.record(s, task_id) for s in study.systems}, facts)

    def record(self, system: str, task_id: str) -> RunRecord:
        return self.records[(system, task_id)]

    def score(self, system: str, task_id: str) -> RunScore:
        return self.records[(system, task_id)].score


@dataclass
class RunView:
    """What a card shows of one scored run: ``states (N, P, 7)`` its checkpoints and
    ``final (P, 7)`` its final state, both aligned onto the target; ``recorded_final (P, 7)`` the
    final state as recorded (world frame, unregistered); ``calls`` its tool calls."""

    system: str
    score: RunScore
    states: np.ndarray
    final: np.ndarray
    calls: list = field(default_factory=list)
    note: str = ""
    recorded_final: np.ndarray | None = None


def _recorded_states(run_dir: Path, task_id: str, part_ids: list[str]):
    """``(checkpoint poses (N, P, 7) or None, calls)`` of a run's trajectory, read once."""
    tpath = run_dir / "trajectory.jsonl"
    if not tpath.is_file():
        return None, []
    try:
        traj = read_trajectory(tpath)
    except FormatError:
        return None, []
    if traj.header.task_id != task_id or not set(part_ids) <= set(traj.header.part_ids):
        return None, []
    return np.stack([poses_array(c.poses, part_ids) for c in traj.checkpoints()]), traj.calls


def load_run_view(study: TaskRuns, system: str, task_id: str, scene: TaskScene) -> RunView | None:
    """The run's recorded states, aligned; None when it was not scored or its states cannot be
    read again. The final state comes from where its scoring took it (``final_from``)."""
    rec = study.record(system, task_id)
    r = rec.score
    if not r.scored or rec.run_dir is None:
        return None
    run_dir = Path(rec.run_dir)
    ck_poses, calls = _recorded_states(run_dir, task_id, scene.part_ids)
    try:
        if r.final_from == "final.json":
            final = poses_array(read_final(run_dir / "final.json").poses, scene.part_ids)
        elif ck_poses is not None:
            final = ck_poses[-1]
        else:
            return None
    except (FormatError, KeyError):
        return None
    note = ""
    if len(r.reg_rotation) == 0:
        note = "drawn unregistered: the cached scores predate saved registrations (rescore with a fresh --out)"
    recorded_final = final
    final = aligned_poses(final, r.reg_rotation, r.reg_translation, scene.divisor)
    states = np.zeros((0, len(scene.part_ids), 7))
    if len(r.ck_pa) and ck_poses is not None and len(ck_poses) == len(r.ck_pa):
        states = ck_poses
        if len(r.ck_reg_rotation) == len(r.ck_pa):
            states = aligned_poses(ck_poses, r.ck_reg_rotation, r.ck_reg_translation, scene.divisor)
    elif len(r.ck_pa):
        note = "the trajectory changed since it was scored: checkpoints not shown"
    return RunView(system, r, states, final, calls, note, recorded_final)


# ---------------------------------------------------------------- numbers
def _pa(x: float) -> str:
    return f"{fixed(100 * x, 1)}%"


def _scd(x: float) -> str:
    return fixed(1000 * x, 2) if np.isfinite(x) else DASH


def _run_numbers(r: RunScore) -> str:
    return f"PA {_pa(r.pa)} · SR {int(r.sr)} · SCD {_scd(r.scd)}"


def _img(src: str, alt: str, size: tuple[int, int]) -> str:
    return (
        f'<img src="{html.escape(src)}" alt="{html.escape(alt)}" width="{size[0]}" height="{size[1]}" loading="lazy">'
    )


def _x_of(r: RunScore) -> np.ndarray:
    """Normalized time of each checkpoint (first to last call)."""
    if len(r.call_t) == 0:
        return np.zeros(len(r.ck_t))
    t0, t1 = float(r.call_t.min()), float(r.call_t.max())
    return np.clip((np.asarray(r.ck_t) - t0) / max(t1 - t0, 1e-9), 0.0, 1.0)


# ---------------------------------------------------------------- card parts
@dataclass
class Picture:
    """One picture of a card's first row: the target or a system's final state (``src`` None:
    no picture, ``numbers`` says why)."""

    label: str
    src: str | None
    numbers: str
    target: bool = False


def _final_pictures(
    scene: TaskScene | None, views: dict[str, RunView], study: TaskRuns, task_id: str, camera, folder: Path, rel: str
) -> list[Picture]:
    out = []
    if scene is not None:
        out.append(Picture("Target", rel + scene.render(scene.target_poses, camera, CARD_SIZE, folder), "", True))
    for s in study.systems:
        r = study.score(s, task_id)
        v = views.get(s)
        src = rel + scene.render(v.final, camera, CARD_SIZE, folder) if v is not None and scene is not None else None
        if r.scored:
            nums = _run_numbers(r) if src is not None else f"{_run_numbers(r)} · no picture"
        else:
            nums = f"{r.status}: {'; '.join(r.problems) or r.status} (PA = SR = 0)"
        out.append(Picture(s, src, nums))
    return out


def _finals(pictures: list[Picture], views: dict[str, RunView]) -> str:
    figs = []
    for p in pictures:
        if p.src is not None:
            pic = _img(p.src, "target" if p.target else f"{p.label} final state", CARD_SIZE)
        else:
            pic = (
                f'<div class="nopic" style="width:{CARD_SIZE[0]}px;height:{CARD_SIZE[1]}px">'
                f"{html.escape(p.numbers)}</div>"
            )
        v = views.get(p.label)
        note = f'<br><span class="note">{html.escape(v.note)}</span>' if v is not None and v.note else ""
        nums = f"<br>{html.escape(p.numbers)}" if p.numbers and p.src is not None else ""
        figs.append(f"<figure>{pic}<figcaption><b>{html.escape(p.label)}</b>{nums}{note}</figcaption></figure>")
    return f'<div class="finals">{"".join(figs)}</div>'


HINT_GAP = 0.25  # share of parts placed minus PA from which a card explains the difference


def registration_hint(scene: TaskScene, view: RunView, threshold: float) -> str:
    """Why a run's PA is far below the share of its parts that lie at their targets as placed
    (:meth:`TaskScene.placed`), or ``""`` when it is not: the scorer moves the whole assembly
    with one rigid registration, so parts left elsewhere pull it off the parts in place."""
    r = view.score
    if view.recorded_final is None or not len(scene.part_ids):
        return ""
    placed = scene.placed(view.recorded_final, threshold)
    away = np.flatnonzero(~placed)
    if placed.mean() - r.pa < HINT_GAP or not len(away):
        return ""
    named = [scene.part_ids[i] + ("" if i < len(r.moved) and r.moved[i] else " (never moved)") for i in away[:4]]
    more = f" and {len(away) - 4} more" if len(away) > 4 else ""
    return (
        f"{view.system}: {int(placed.sum())} of {len(placed)} parts lie at their targets as placed, yet PA is "
        f"{_pa(r.pa)}. The scorer registers the whole assembly with ONE rigid transform before it compares "
        f"parts, so the {'part' if len(away) == 1 else 'parts'} left away, {', '.join(named)}{more}, "
        f"{'pulls' if len(away) == 1 else 'pull'} that transform off the parts in place."
    )


def _part_table(scene_ids: list[str], colors: np.ndarray | None, study: TaskRuns, doc_runs: dict, task_id: str) -> str:
    systems = [s for s in study.systems if study.score(s, task_id).scored]
    if not systems:
        return ""
    head = "<th>Part</th>" + "".join(f'<th class="r">{html.escape(s)} CD ×1000</th><th>class</th>' for s in systems)
    rows = []
    for i, pid in enumerate(scene_ids):
        sw = ""
        if colors is not None:
            c = "#" + "".join(f"{int(round(255 * x)):02x}" for x in colors[i])
            sw = f'<span class="sw" style="background:{c}"></span>'
        tds = f'<td class="l">{sw}{html.escape(pid)}</td>'
        for s in systems:
            r = study.score(s, task_id)
            e = float(r.part_errors[i]) if i < len(r.part_errors) else float("nan")
            cls = (doc_runs[(s, task_id)].get("part_classes") or [""] * (i + 1))[i] if (s, task_id) in doc_runs else ""
            tds += (
                f'<td class="r" data-v="{"" if not np.isfinite(e) else f"{1000 * e:.6g}"}">{fixed(1000 * e, 2)}</td>'
                f'<td class="l {"ok" if cls == "correct" else ""}">{html.escape(cls.replace("_", " "))}</td>'
            )
        rows.append(f"<tr>{tds}</tr>")
    return (
        scroll_box(
            f'<table class="sortable parts"><thead><tr>{head}</tr></thead><tbody>{"".join(rows)}</tbody></table>'
        )
        + '<p class="note">Matched part Chamfer distance (normalized units, ×1000) of the final state; a part is '
        "correct at or below 10. Classes: the geometric failure classes of Table A-11.</p>"
    )


def _curves(study: TaskRuns, task_id: str, views: dict[str, RunView], colors: dict[str, str]) -> str:
    pa, scd = [], []
    for s in study.systems:
        r = study.score(s, task_id)
        if not r.scored:
            continue
        if len(r.ck_pa):
            xs = list(_x_of(r)) + [1.0]
            pa.append(Series(s, colors[s], xs, [100 * v for v in r.ck_pa] + [100 * r.pa]))
            scd.append(Series(s, colors[s], xs, [1000 * v for v in r.ck_scd] + [1000 * r.scd]))
        else:
            pa.append(Series(s, colors[s], [0.0, 1.0], [100 * r.pa] * 2))
            scd.append(Series(s, colors[s], [0.0, 1.0], [1000 * r.scd] * 2))
    if not pa:
        return ""
    legend = "".join(
        f'<span class="key"><span class="sw" style="background:{colors[s.label]}"></span>{html.escape(s.label)}</span>'
        for s in pa
    )
    return (
        f'<div class="curves">{step_chart(pa, "PA (%) over normalized time", (0, 100), fmt=lambda v: f"{v:.0f}")}'
        f"{step_chart(scd, 'SCD ×1000 over normalized time', fmt=lambda v: fixed(v, 0 if v >= 100 else 2))}"
        f'<div class="legend">{legend}</div></div>'
    )


def _filmstrip(view: RunView, scene: TaskScene, camera, folder: Path, rel: str) -> str:
    r = view.score
    frames = []
    for u, k in zip(NORMALIZED_POINTS, normalized_states(r), strict=True):
        if k is None or len(view.states) == 0:
            poses, pa, scd = view.final, r.pa, r.scd
        else:
            poses, pa, scd = view.states[k], float(r.ck_pa[k]), float(r.ck_scd[k])
        pic = _img(rel + scene.render(poses, camera, FRAME_SIZE, folder), f"{view.system} at {u:g}", FRAME_SIZE)
        frames.append(f"<figure>{pic}<figcaption>t={u:g}<br>PA {_pa(pa)}<br>SCD {_scd(scd)}</figcaption></figure>")
    return f'<div class="filmstrip">{"".join(frames)}</div>'


def _calls(view: RunView, task_id: str, data_src: str | None) -> str:
    """A collapsed list of the run's tool calls, filled from the task's data file when opened
    (a paper-scale study has ~10^5 calls: listing them inline would make the page slow to open)."""
    if not view.calls:
        return '<p class="note">No trajectory: no tool calls.</p>'
    if data_src is None:
        return f'<p class="note">{len(view.calls)} tool calls (trajectory.jsonl).</p>'
    return (
        f'<details class="calls" data-task="{html.escape(task_id)}" data-src="{html.escape(data_src)}" '
        f'data-system="{html.escape(view.system)}"><summary>Tool calls ({len(view.calls)})</summary>'
        '<ul class="calls"></ul></details>'
    )


def _call_rows(view: RunView) -> list[list[Any]]:
    """``[seq, t, tool, arguments (JSON, cut at 160 characters), ok, error]`` per call, at most
    :data:`MAX_LISTED_CALLS`."""
    rows = []
    for c in view.calls[:MAX_LISTED_CALLS]:
        args = orjson.dumps(c.args).decode()
        rows.append(
            [
                c.seq,
                round(float(c.t), 2),
                c.tool,
                args if len(args) <= 160 else args[:157] + "...",
                bool(c.ok),
                c.error or "",
            ]
        )
    return rows


NO_MESHES = "The suite has no meshes for this task (an official package): no pictures."


@dataclass
class Card:
    """One task's card: its HTML and the pictures of its first row (target, final states)."""

    html: str
    pictures: list[Picture]


def task_card(
    study: TaskRuns,
    task: dict[str, Any],
    doc_runs: dict,
    scene: TaskScene | None,
    views: dict[str, RunView],
    folder: Path,
    rel: str,
    viewer_src: str | None,
    colors: dict[str, str],
    no_pictures: str = NO_MESHES,
    threshold: float = ProtocolSettings.threshold,
    viewer_url: str | None = None,
) -> Card:
    """One task's card; pictures are rendered into ``folder`` (``rel``: its path from the page);
    without a ``scene`` the card says ``no_pictures`` instead. ``threshold``: the protocol's
    part-correct threshold (for the note on parts placed but not counted). ``viewer_url``: an
    ``aw-view`` of the same runs folder, which each run links to (:func:`episode_link`)."""
    tid = task["task_id"]
    camera = None
    if scene is not None:
        camera = scene.camera([v.final for v in views.values()])
    meta = " · ".join(
        str(x)
        for x in (task["source"], task["condition"], task["category"], f"{task['n_parts']} parts", task["variant"])
        if x
    )
    pictures = _final_pictures(scene, views, study, tid, camera, folder, rel)
    parts = [
        f'<section class="card" id="task-{slug(tid)}"><h3>{html.escape(tid)}</h3><p class="meta">{html.escape(meta)}</p>',
        _finals(pictures, views),
    ]
    if viewer_url:
        links = [
            f'<a class="live" href="{html.escape(episode_link(viewer_url, s, tid))}">{html.escape(s)}</a>'
            for s in study.systems
            if study.record(s, tid).run_dir is not None
        ]
        if links:
            parts.append(f'<p class="note">Episode pages in aw-view: {" · ".join(links)}</p>')
    if scene is None:
        parts.append(f'<p class="note">{html.escape(no_pictures)}</p>')
    else:
        for s in study.systems:
            hint = registration_hint(scene, views[s], threshold) if s in views else ""
            if hint:
                parts.append(f'<p class="hint">{html.escape(hint)}</p>')
    parts.append(_curves(study, tid, views, colors))
    parts.append(
        _part_table(
            scene.part_ids if scene else (study.facts[tid].part_ids if tid in study.facts else []),
            scene.colors if scene else None,
            study,
            doc_runs,
            tid,
        )
    )
    for s in study.systems:
        v = views.get(s)
        if v is None:
            continue
        parts.append(f'<div class="run"><h4>{html.escape(s)}</h4>')
        if scene is not None:
            parts.append(_filmstrip(v, scene, camera, folder, rel))
        parts.append(_calls(v, tid, viewer_src) + "</div>")
    if viewer_src is not None:
        parts.append(
            f'<button class="open3d" data-task="{html.escape(tid)}" data-src="{html.escape(viewer_src)}">'
            'Open the 3D view</button><div class="viewer" hidden></div>'
        )
    parts.append("</section>")
    return Card("".join(parts), pictures)


# ---------------------------------------------------------------- 3D viewer data
def _pick(n: int, k: int) -> list[int]:
    if n <= k:
        return list(range(n))
    return sorted({int(round(i)) for i in np.linspace(0, n - 1, k)})


def viewer_data(scene: TaskScene, views: dict[str, RunView]) -> dict[str, Any]:
    """The data file of one task: for the 3D view, decimated part meshes (baked frame), the target
    poses, and per system its recorded states (aligned poses, PA, SCD), at most
    :data:`MAX_VIEWER_STATES` of them plus the final state; per system its tool calls."""
    parts = display_parts(scene.part_ids, scene.meshes, scene.colors)
    systems = {}
    for s, view in views.items():
        r = view.score
        states = []
        for k in _pick(len(view.states), MAX_VIEWER_STATES):
            states.append(
                {
                    "label": f"checkpoint {k} (call {int(r.ck_seq[k])}, {float(r.ck_t[k]):.1f} s)",
                    "pa": 100 * float(r.ck_pa[k]),
                    "scd": 1000 * float(r.ck_scd[k]),
                    "poses": np.round(view.states[k], 6).tolist(),
                }
            )
        states.append(
            {
                "label": "final state",
                "pa": 100 * r.pa,
                "scd": 1000 * r.scd if np.isfinite(r.scd) else None,
                "poses": np.round(view.final, 6).tolist(),
            }
        )
        systems[s] = {
            "states": states,
            "n_recorded": int(len(view.states)),
            "calls": _call_rows(view),
            "n_calls": len(view.calls),
        }
    return {
        "task_id": scene.task_id,
        "parts": parts,
        "target": np.round(scene.target_poses, 6).tolist(),
        "systems": systems,
    }
