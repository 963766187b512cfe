"""One recorded run turned into arrays: checkpoint poses, the final state, the call log and the
pose edits with their magnitudes. No evaluator here: this is pure bookkeeping on the recording.

Pose arrays follow the evaluator's part order (``geom.part_ids``: scored parts, distractors
excluded); a missing-part task simply has fewer parts. Checkpoints are the initial state and the
state after every pose-changing call (:meth:`aw.formats.Trajectory.checkpoints`). The final state
is ``final.json`` when present, valid for this task and in agreement with the trajectory's last
recorded state, else that state (a contradiction is a listed problem; ``trust_final`` keeps
final.json); which one was used is reported.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from aw.formats import FormatError, read_final, read_trajectory
from aw.formats.agreement import contradicting_parts
from aw.pose import normalize_quaternion, quat_to_matrix

__all__ = [
    "INSPECT_TOOLS",
    "OBSERVE_TOOLS",
    "MANIPULATE_TOOLS",
    "KIND_NAMES",
    "call_kind",
    "RunUnreadable",
    "EpisodeArrays",
    "poses_array",
    "edit_magnitudes",
    "read_episode",
    "ROTATION_CUTOFF_DEG",
]

INSPECT_TOOLS = frozenset({"list_objects", "get_object", "get_scene", "get_state"})
OBSERVE_TOOLS = frozenset({"capture_scene", "move_camera"})
MANIPULATE_TOOLS = frozenset({"translate_objects", "rotate_objects", "set_object_pose"})
# Call kinds (Appendix C.1); "other" (grouping, start_episode, unknown tools) stays in the denominator.
KIND_NAMES = ("inspect", "observe", "manipulate", "other")
# Edits rotating every affected part by less than this count as translations (Appendix C.1).
ROTATION_CUTOFF_DEG = 0.5


def call_kind(tool: str) -> int:
    """Index into :data:`KIND_NAMES` of a tool name."""
    if tool in INSPECT_TOOLS:
        return 0
    if tool in OBSERVE_TOOLS:
        return 1
    if tool in MANIPULATE_TOOLS:
        return 2
    return 3


class RunUnreadable(Exception):
    """Neither the trajectory nor final.json gives a usable state for this task."""


@dataclass
class EpisodeArrays:
    """Arrays of one run (``P`` scored parts, ``N`` checkpoints, ``C`` calls, ``E`` edits).

    Attributes:
        ck_seq, ck_t: ``(N,)`` call sequence number (0 = initial state) and time in seconds.
        ck_poses: ``(N, P, 7)`` poses at each checkpoint.
        final_poses: ``(P, 7)``; ``final_from`` is ``"final.json"`` or ``"trajectory"``.
        moved: ``(P,)`` whether the part's pose ever changed (any edit, or a final pose that
            differs from the initial one).
        call_t, call_kind, call_ok: ``(C,)`` time, :data:`KIND_NAMES` index, success.
        edit_call: ``(E,)`` index into the calls of each pose-changing manipulation.
        edit_translation: ``(E,)`` largest part-centroid displacement over affected parts,
            divided by the evaluation divisor (largest-part diagonal).
        edit_rotation_deg: ``(E,)`` largest rotation angle over affected parts.
        edit_revisit: ``(E,)`` whether the edit touches a part an earlier edit touched.
        end_t: time of the end record (else of the last call, else 0).
    """

    ck_seq: np.ndarray
    ck_t: np.ndarray
    ck_poses: np.ndarray
    final_poses: np.ndarray
    final_from: str
    moved: np.ndarray
    call_t: np.ndarray
    call_kind: np.ndarray
    call_ok: np.ndarray
    edit_call: np.ndarray
    edit_translation: np.ndarray
    edit_rotation_deg: np.ndarray
    edit_revisit: np.ndarray
    end_t: float
    end_reason: str | None
    truncated: bool
    has_trajectory: bool
    problems: list[str] = field(default_factory=list)


def poses_array(poses: Mapping[str, Sequence[float]], part_ids: Sequence[str]) -> np.ndarray:
    """``(P, 7)`` poses in ``part_ids`` order with unit quaternions (w >= 0 not enforced)."""
    arr = np.array([poses[p] for p in part_ids], dtype=np.float64).reshape(len(part_ids), 7)
    arr[:, 3:] = normalize_quaternion(arr[:, 3:])
    return arr


def edit_magnitudes(
    before: np.ndarray, after: np.ndarray, centroids: np.ndarray, divisor: float
) -> tuple[np.ndarray, np.ndarray]:
    """Per-part centroid displacement (divided by ``divisor``) and rotation angle in degrees.

    ``before, after: (..., A, 7)``; ``centroids: (A, 3)`` baked-frame part centroids.
    Returns ``(translation (..., A), rotation_deg (..., A))``.
    """
    rb = quat_to_matrix(before[..., 3:])
    ra = quat_to_matrix(after[..., 3:])
    cb = np.einsum("...ij,...j->...i", rb, np.broadcast_to(centroids, before.shape[:-1] + (3,))) + before[..., :3]
    ca = np.einsum("...ij,...j->...i", ra, np.broadcast_to(centroids, after.shape[:-1] + (3,))) + after[..., :3]
    trans = np.linalg.norm(ca - cb, axis=-1) / divisor
    # angle of ra rb^T from its trace; clip guards rounding just outside [-1, 1]
    rel = np.einsum("...ij,...kj->...ik", ra, rb)
    cos = np.clip((np.trace(rel, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    # for tiny angles the trace loses precision; use the antisymmetric part there
    skew = np.stack(
        [rel[..., 2, 1] - rel[..., 1, 2], rel[..., 0, 2] - rel[..., 2, 0], rel[..., 1, 0] - rel[..., 0, 1]], -1
    )
    sin = np.linalg.norm(skew, axis=-1) / 2.0
    rot = np.degrees(np.arctan2(sin, cos))
    return trans, rot


def _read_final_state(run_dir: Path, task_id: str, all_part_ids: Sequence[str], problems: list[str]):
    path = run_dir / "final.json"
    if not path.is_file():
        return None
    try:
        final = read_final(path)
    except FormatError as exc:
        problems.append(f"final.json unreadable ({exc.problem})")
        return None
    if final.task_id != task_id:
        problems.append(f"final.json is for task {final.task_id!r}, not {task_id!r}; ignored")
        return None
    missing = sorted(set(all_part_ids) - set(final.poses))
    if missing:
        problems.append(f"final.json lacks poses of parts {missing}; ignored")
        return None
    unknown = sorted(set(final.poses) - set(all_part_ids))
    if unknown:
        problems.append(f"final.json names parts {unknown} that task {task_id!r} does not have; ignored")
        return None
    return final


def read_episode(
    run_dir: str | Path,
    task_id: str,
    all_part_ids: Sequence[str],
    scored_ids: Sequence[str],
    centroids: np.ndarray,
    divisor: float,
    *,
    final_only: bool = False,
    trust_final: bool = False,
) -> EpisodeArrays:
    """Read ``run_dir``'s trajectory and final.json for ``task_id``.

    ``all_part_ids``: the task's parts (distractors included) with ``centroids: (A, 3)`` in the
    same order; ``scored_ids``: the evaluator's parts, a subset. A ``final.json`` that contradicts
    the trajectory's last recorded state is a problem, and the trajectory's state is scored unless
    ``trust_final``. Raises :class:`RunUnreadable`
    when no usable state exists; recoverable damage (a cut last line, a bad final.json next to a
    good trajectory) is listed in ``problems``.
    """
    run_dir = Path(run_dir)
    problems: list[str] = []
    traj = None
    tpath = run_dir / "trajectory.jsonl"
    if tpath.is_file():
        try:
            traj = read_trajectory(tpath)
        except FormatError as exc:
            problems.append(f"trajectory unreadable: {exc}")
        if traj is not None:
            if traj.header.task_id != task_id:
                problems.append(f"trajectory is for task {traj.header.task_id!r}, not {task_id!r}; ignored")
                traj = None
            elif set(traj.header.part_ids) != set(all_part_ids):
                problems.append(
                    f"trajectory part ids {sorted(traj.header.part_ids)} differ from the task's "
                    f"{sorted(all_part_ids)}; ignored"
                )
                traj = None
            else:
                problems += [f"trajectory: {p}" for p in traj.problems]
    final = _read_final_state(run_dir, task_id, all_part_ids, problems)
    if traj is None and final is None:
        raise RunUnreadable("; ".join(problems) or "no trajectory.jsonl or final.json")

    ids = list(all_part_ids)
    scored_idx = np.array([ids.index(p) for p in scored_ids], dtype=np.int64)
    if traj is not None:
        checkpoints = traj.checkpoints()
        all_poses = np.stack([poses_array(c.poses, ids) for c in checkpoints])  # (N, A, 7)
        ck_seq = np.array([c.seq for c in checkpoints], dtype=np.int64)
        ck_t = np.array([c.t for c in checkpoints], dtype=np.float64)
        calls = traj.calls
        call_t = np.array([c.t for c in calls], dtype=np.float64)
        call_kind_arr = np.array([call_kind(c.tool) for c in calls], dtype=np.int8)
        call_ok = np.array([c.ok for c in calls], dtype=bool)
        end_reason = traj.end.reason if traj.end is not None else None
        end_t = float(traj.end.t or 0.0) if traj.end is not None else (float(call_t[-1]) if len(calls) else 0.0)
        # pose-changing calls, in order, aligned with checkpoints 1..N-1
        changing = [i for i, c in enumerate(calls) if c.poses is not None]
        trans, rot = edit_magnitudes(all_poses[:-1], all_poses[1:], centroids, divisor)  # (N-1, A)
        edit_call, edit_t, edit_r, revisit = [], [], [], []
        edited: set[str] = set()
        moved = np.zeros(len(ids), dtype=bool)
        for k, ci in enumerate(changing):
            call = calls[ci]
            affected = [ids.index(p) for p in (call.changed or [])]
            if not affected:  # poses recorded without a changed list: infer from the poses
                affected = list(np.flatnonzero(np.any(all_poses[k + 1] != all_poses[k], axis=-1)))
            moved[affected] = True
            if call.tool not in MANIPULATE_TOOLS or not affected:
                continue
            edit_call.append(ci)
            edit_t.append(float(trans[k, affected].max()))
            edit_r.append(float(rot[k, affected].max()))
            names = {ids[a] for a in affected}
            revisit.append(bool(names & edited))
            edited |= names
        if traj.end is not None:
            # The end record is written from the scene like every call line, so it repeats the last
            # recorded state; a difference means edits were made that no call line records.
            gap = contradicting_parts(traj.end.poses, checkpoints[-1].poses, ids)
            if gap:
                problems.append(
                    f"trajectory: the end record's poses contradict the last recorded call's (parts "
                    f"{gap}): edits were made that were not recorded"
                )
        if final is not None:
            differ = contradicting_parts(final.poses, traj.final_poses(), ids)
            if differ:
                kept = "final.json (--trust-final)" if trust_final else "the trajectory's"
                problems.append(
                    f"final.json contradicts the trajectory's last recorded state (parts {differ}); scored {kept}"
                )
                if not trust_final:
                    final = None
        final_all = poses_array(final.poses, ids) if final is not None else poses_array(traj.final_poses(), ids)
        if final is None and traj.end is None and not (run_dir / "final.json").is_file():
            problems.append("no final.json and no end record: scored the last recorded state")
        moved |= np.any(np.abs(final_all - all_poses[0]) > 1e-9, axis=-1)
        return EpisodeArrays(
            ck_seq=ck_seq if not final_only else ck_seq[:0],
            ck_t=ck_t if not final_only else ck_t[:0],
            ck_poses=all_poses[:, scored_idx] if not final_only else all_poses[:0, scored_idx],
            final_poses=final_all[scored_idx],
            final_from="final.json" if final is not None else "trajectory",
            moved=moved[scored_idx],
            call_t=call_t,
            call_kind=call_kind_arr,
            call_ok=call_ok,
            edit_call=np.array(edit_call, dtype=np.int64),
            edit_translation=np.array(edit_t, dtype=np.float64),
            edit_rotation_deg=np.array(edit_r, dtype=np.float64),
            edit_revisit=np.array(revisit, dtype=bool),
            end_t=end_t,
            end_reason=end_reason,
            truncated=bool(traj.truncated),
            has_trajectory=True,
            problems=problems,
        )
    # final.json alone: no checkpoints, no call log; "moved" relative to the identity initial pose
    final_all = poses_array(final.poses, ids)
    identity = np.array([0, 0, 0, 1, 0, 0, 0], dtype=np.float64)
    empty_f = np.zeros(0)
    return EpisodeArrays(
        ck_seq=np.zeros(0, dtype=np.int64),
        ck_t=empty_f,
        ck_poses=np.zeros((0, len(scored_idx), 7)),
        final_poses=final_all[scored_idx],
        final_from="final.json",
        moved=np.any(np.abs(final_all - identity) > 1e-9, axis=-1)[scored_idx],
        call_t=empty_f,
        call_kind=np.zeros(0, dtype=np.int8),
        call_ok=np.zeros(0, dtype=bool),
        edit_call=np.zeros(0, dtype=np.int64),
        edit_translation=empty_f,
        edit_rotation_deg=empty_f,
        edit_revisit=np.zeros(0, dtype=bool),
        end_t=0.0,
        end_reason=final.reason,
        truncated=False,
        has_trajectory=False,
        problems=problems,
    )
