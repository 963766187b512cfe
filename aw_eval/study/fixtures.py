"""Small box suites and scripted runs, for ``aw-score``'s tests and benchmarks.

:func:`box_suite` writes a real suite (manifest, task directories with OBJ meshes and PNG
references, hidden targets) through :mod:`aw.formats`: every object is a stack of boxes of
distinct sizes (no equivalent parts), baked into a separated layout by a yaw and a translation
per part, so the target pose of a part is the inverse of its layout. :func:`write_scripted_run`
records a run like ``aw-serve`` would (``TrajectoryWriter``, ``final.json``, ``run.json``):
inspection and camera calls, a large "inspection" move of every part, then a placement that is
exact for the parts listed as correct and off by a chosen offset for the others.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
from PIL import Image

from aw.formats import (
    Condition,
    EndReason,
    FinalState,
    PartTarget,
    RunInfo,
    SuiteEntry,
    SuiteManifest,
    Targets,
    Task,
    TaskPart,
    TrajectoryCall,
    TrajectoryEnd,
    TrajectoryHeader,
    TrajectoryWriter,
    VariantKind,
    read_targets,
    read_task,
    write_final,
    write_manifest,
    write_run_info,
    write_targets,
    write_task,
)
from aw.formats.suite import suite_paths
from aw.formats.targets import Variant
from aw.pose import compose_poses, invert_pose, poses_to_matrices, quat_from_axis_angle

__all__ = ["BLOCKS", "box_suite", "write_scripted_run", "ScriptedRun"]

BLOCKS: tuple[tuple[str, tuple[Condition, ...]], ...] = (
    ("partnet", ("none", "image")),
    ("ikea_manual", ("manual",)),
    ("assemblybench", ("manual",)),
    ("fantastic_breaks", ("none",)),
)
_PROMPT = "Assemble the supplied parts into a coherent object."
IDENTITY = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]


def _object_parts(n_parts: int, rng: np.random.Generator) -> list[trimesh.Trimesh]:
    """Boxes of distinct sizes stacked along Z (assembled frame)."""
    parts, z = [], 0.0
    for i in range(n_parts):
        ext = np.array([0.5 - 0.07 * i, 0.3 + 0.05 * i, 0.08 + 0.03 * i]) * rng.uniform(0.9, 1.1, 3)
        m = trimesh.creation.box(extents=ext)
        m.apply_translation([0.0, 0.0, z + ext[2] / 2])
        z += ext[2]
        parts.append(m)
    return parts


def _layout(n_parts: int, rng: np.random.Generator) -> np.ndarray:
    """``(P, 7)`` layout poses: yaw plus a spread along X/Y."""
    out = []
    for i in range(n_parts):
        q = quat_from_axis_angle(np.array([0.0, 0.0, 1.0]), rng.uniform(-np.pi, np.pi))
        out.append([1.2 * i, 0.8 * (i % 2), 0.0, *q])
    return np.array(out)


def _reference_png(path: Path, shade: int) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.new("RGB", (64, 48), (shade, 120, 200)).save(path)


def _write_task(
    root: Path,
    tid: str,
    source: str,
    cond: Condition,
    object_id: str,
    category: str,
    assembled: list[trimesh.Trimesh],
    layout: np.ndarray,
    *,
    distractor: frozenset[int] = frozenset(),
    eval_divisor: float | None = None,
    variant: Variant | None = None,
) -> None:
    task_dir, targets_path = suite_paths(root, tid)
    (task_dir / "parts").mkdir(parents=True, exist_ok=True)
    parts, targets = [], {}
    for i, m in enumerate(assembled):
        pid = f"p{i + 1:02d}"
        baked = m.copy()
        baked.apply_transform(poses_to_matrices(layout[i]))
        baked.export(task_dir / "parts" / f"{pid}.obj")
        parts.append(TaskPart(id=pid, mesh=f"parts/{pid}.obj"))
        targets[pid] = PartTarget(pose=[float(x) for x in invert_pose(layout[i])], distractor=i in distractor)
    refs = []
    if cond != "none":
        for r in range(2 if cond == "manual" else 1):
            _reference_png(task_dir / "references" / f"{r + 1:02d}.png", 40 * r + 20)
            refs.append(f"references/{r + 1:02d}.png")
    write_task(
        task_dir,
        Task(
            task_id=tid,
            source=source,
            dataset="boxes",
            category=category,
            object_id=object_id,
            condition=cond,
            prompt=_PROMPT,
            parts=parts,
            references=refs,
        ),
    )
    write_targets(
        targets_path,
        Targets(task_id=tid, parts=targets, scale=1.0, eval_divisor=eval_divisor, variant=variant or Variant()),
    )


def box_suite(
    root: str | Path,
    *,
    objects_per_source: int = 1,
    n_parts: int | Sequence[int] = 3,
    blocks: Sequence[tuple[str, Sequence[Condition]]] = BLOCKS,
    variants: bool = False,
    seed: int = 0,
    name: str = "box-suite",
) -> Path:
    """Write a suite under ``root``; returns ``root``. ``n_parts`` may cycle over objects.

    ``variants`` adds, for the first object of the first block (every condition), the Appendix E
    variants paired by ``base_task_id``: ``-layout_a`` (same parts, another layout),
    ``-distractor`` (an extra box flagged as a distractor, last) and ``-missing`` (the last part
    removed; the targets keep the full object's ``eval_divisor``).
    """
    from aw.prepare.geometry import eval_divisor as _eval_divisor

    root = Path(root)
    counts = [n_parts] if isinstance(n_parts, int) else list(n_parts)
    rng = np.random.default_rng(seed)
    entries: list[SuiteEntry] = []
    k = 0
    for bi, (source, conditions) in enumerate(blocks):
        for o in range(objects_per_source):
            p = counts[k % len(counts)]
            k += 1
            assembled = _object_parts(p, rng)
            layout = _layout(p, rng)
            object_id = f"box{o:03d}"
            category = ("chair", "table")[o % 2]
            extra: list[tuple[VariantKind, str, list[trimesh.Trimesh], np.ndarray, frozenset[int], float | None]] = []
            if variants and bi == 0 and o == 0:
                spare = trimesh.creation.box(extents=[0.12, 0.12, 0.12])
                spare.apply_translation([2.0, 2.0, 0.06])
                baked = [m.copy().apply_transform(poses_to_matrices(layout[i])) for i, m in enumerate(assembled)]
                extra = [
                    ("layout", "-layout_a", assembled, _layout(p, rng), frozenset(), None),
                    ("distractor", "-distractor", assembled + [spare], _layout(p + 1, rng), frozenset({p}), None),
                    ("missing", "-missing", assembled[:-1], layout[:-1], frozenset(), _eval_divisor(baked)),
                ]
            for cond in conditions:
                base = f"{source}-{object_id}-{cond}"
                _write_task(root, base, source, cond, object_id, category, assembled, layout)
                entries.append(
                    SuiteEntry(
                        task_id=base, source=source, condition=cond, object_id=object_id, category=category, n_parts=p
                    )
                )
                for kind, suffix, parts, lay, distractor, divisor in extra:
                    tid = base + suffix
                    _write_task(
                        root,
                        tid,
                        source,
                        cond,
                        object_id,
                        category,
                        parts,
                        lay,
                        distractor=distractor,
                        eval_divisor=divisor,
                        variant=Variant(kind=kind, base_task_id=base),
                    )
                    entries.append(
                        SuiteEntry(
                            task_id=tid,
                            source=source,
                            condition=cond,
                            object_id=object_id,
                            category=category,
                            n_parts=len(parts) - len(distractor),
                            variant=kind,
                            base_task_id=base,
                        )
                    )
    write_manifest(root, SuiteManifest(name=name, generator="aw_eval.study.fixtures", seed=seed, tasks=entries))
    return root


@dataclass
class ScriptedRun:
    """What :func:`write_scripted_run` recorded: checkpoints written and the final poses."""

    n_checkpoints: int
    final_poses: dict[str, list[float]]


def write_scripted_run(
    run_dir: str | Path,
    suite_dir: str | Path,
    task_id: str,
    *,
    system: str,
    correct: Sequence[str] | None = None,
    wrong_offset: float = 0.3,
    jitter_edits: int = 0,
    dt: float = 2.0,
    end_reason: EndReason | None = "finished",
    write_final_json: bool = True,
    cut_last_line: bool = False,
    run_info: dict | None = None,
    seed: int = 0,
    inspect_moves: bool = True,
    jitter_scale: float = 1e-3,
) -> ScriptedRun:
    """Record one scripted episode of ``task_id`` into ``run_dir``.

    Parts in ``correct`` (default: all) end at their target pose; the others at the target
    moved by ``wrong_offset`` along X. ``jitter_edits`` adds small random nudges (normal, scale
    ``jitter_scale`` per axis) after the placements, each a new state, for long trajectories. ``end_reason=None`` leaves the
    episode open (no end record, no final.json); ``cut_last_line`` then appends half a call line.
    ``inspect_moves=False`` drops the far move before each placement (fewer checkpoints).
    """
    run_dir = Path(run_dir)
    task_dir, targets_path = suite_paths(suite_dir, task_id)
    task = read_task(task_dir)
    targets = read_targets(targets_path)
    ids = task.part_ids
    correct_set = set(ids if correct is None else correct)
    rng = np.random.default_rng(seed)
    poses = {p: list(IDENTITY) for p in ids}
    header = TrajectoryHeader(
        task_id=task_id,
        system=system,
        started_at="2025-01-01T00:00:00Z",
        part_ids=ids,
        initial_poses={p: list(IDENTITY) for p in ids},
    )
    w = TrajectoryWriter(run_dir / "trajectory.jsonl", header)
    seq, t, n_ck = 0, 0.0, 1

    def call(tool: str, args: dict, changed: Sequence[str] = ()) -> None:
        nonlocal seq, t, n_ck
        seq += 1
        t += dt
        rec = TrajectoryCall(
            seq=seq,
            t=t,
            tool=tool,
            args=args,
            ok=True,
            changed=list(changed),
            poses={p: list(v) for p, v in poses.items()} if changed else None,
        )
        w.call(rec)
        n_ck += bool(changed)

    call("start_episode", {})
    call("list_objects", {})
    call("get_scene", {})
    call("capture_scene", {})
    for pid in ids:
        # an inspection move far away, then the placement
        if inspect_moves:
            poses[pid] = [poses[pid][0] + 2.0, poses[pid][1], poses[pid][2] + 1.0, *poses[pid][3:]]
            call("translate_objects", {"ids": [pid], "delta": [2.0, 0.0, 1.0]}, [pid])
        call("move_camera", {"yaw": 30.0})
        target = np.array(targets.parts[pid].pose)
        if pid not in correct_set:
            target = compose_poses(np.array([wrong_offset, 0, 0, 1, 0, 0, 0]), target)
        poses[pid] = [float(x) for x in target]
        call("set_object_pose", {"id": pid, "position": poses[pid][:3], "quaternion": poses[pid][3:]}, [pid])
        call("capture_scene", {})
    for j in range(jitter_edits):
        # a small random nudge: every jitter edit is a new state (a random walk, no revisits)
        pid = ids[j % len(ids)]
        delta = rng.normal(scale=jitter_scale, size=3)
        poses[pid] = [poses[pid][0] + delta[0], poses[pid][1] + delta[1], poses[pid][2] + delta[2], *poses[pid][3:]]
        call("translate_objects", {"ids": [pid], "delta": delta.tolist()}, [pid])
    call("get_state", {})
    final = {p: list(v) for p, v in poses.items()}
    if end_reason is not None:
        w.end(TrajectoryEnd(reason=end_reason, t=t + dt, poses=final))
        if write_final_json:
            write_final(run_dir / "final.json", FinalState(task_id=task_id, reason=end_reason, poses=final))
    else:
        w.close()
        if cut_last_line:
            with open(run_dir / "trajectory.jsonl", "ab") as fh:
                fh.write(b'{"type": "call", "seq": 999, "t": 1.0, "tool": "transl')
    if run_info is not None:
        write_run_info(run_dir / "run.json", RunInfo(system=system, task_id=task_id, **run_info))
    return ScriptedRun(n_ck, final)
