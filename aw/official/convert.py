"""Official package and episode archives -> this project's suite and runs layout, for ``aw-score``.

::

    SUITE/manifest.json                 one task per (block, sample): ``<block>--<sample slug>``
    SUITE/targets/<task_id>.json        target poses, eval_divisor = the official divisor,
                                        equivalence_hint = the official groups
    SUITE/eval_points/<task_id>.npz     the official evaluation points (1000 per part)
    SUITE/official/<task_id>.episode.zip  the sample's initial episode archive (its world), so
                                        runs recorded on the task export to official archives
    SUITE/official/package.json         the package's identity: the SHA-256 of its benchmark.json
    RUNS/<system>/<task_id>/trajectory.jsonl, final.json, run.json

The converted suite is for scoring: it has no ``tasks/`` folder (the package holds points, not
meshes), and ``aw-score`` takes a task's geometry from its ``eval_points`` file. Every state of
an episode becomes a checkpoint. With episodes, the suite holds the samples they attempted
(as the official evaluation rows them), so a partly downloaded package serves as long as it
holds those samples; without, every sample of the package. Missing files are named all at
once before anything is written.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterable
from datetime import datetime
from pathlib import Path

import numpy as np
import orjson

from aw.formats import (
    EndReason,
    FinalState,
    FormatError,
    PartTarget,
    RunInfo,
    SuiteEntry,
    SuiteManifest,
    Targets,
    write_final,
    write_manifest,
    write_run_info,
    write_targets,
)
from aw.formats.io import staging_dir
from aw.formats.strict_json import read_json_object
from aw.formats.suite import suite_paths
from aw.formats.trajectory import CameraState, TrajectoryCall, TrajectoryEnd, TrajectoryHeader
from aw.official.archive import EpisodeArchive, iso_timestamp, parse_timestamp
from aw.official.episode import PartEpisode, read_part_episode
from aw.official.eval_points import eval_points_path, write_eval_inputs
from aw.official.ids import sample_id_from_slug, task_id_for_sample
from aw.official.package import (
    BENCHMARK_SHA256,
    EXPECTED_SAMPLES,
    REFERENCE_CONDITIONS,
    REPO,
    OfficialPackage,
    file_sha256,
)
from aw.runlock import RunDirBusy, RunDirLock

__all__ = [
    "initial_archive_path",
    "package_record_path",
    "official_benchmark_problem",
    "convert_package",
    "project_camera",
    "end_reason",
    "episode_records",
    "write_episode_run",
    "find_archives",
    "archive_sample",
    "run_log_archives",
    "convert",
]

_NO_CALLS_START = "1970-01-01T00:00:00.000Z"  # an archive without calls has no wall-clock time
_EXTRA_STATE = "state"  # tool name of a state a call recorded beyond its first


def initial_archive_path(suite_dir: str | Path, task_id: str) -> Path:
    return Path(suite_dir) / "official" / f"{task_id}.episode.zip"


def package_record_path(suite_dir: str | Path) -> Path:
    return Path(suite_dir) / "official" / "package.json"


def _write_package_record(pkg: OfficialPackage, out: Path, n_samples: int) -> None:
    record = {
        "format": "assemblyworld.official_package",
        "repo": REPO,
        "benchmark_sha256": file_sha256(pkg.root / "benchmark.json"),
        "samples": n_samples,
    }
    package_record_path(out).write_bytes(orjson.dumps(record, option=orjson.OPT_INDENT_2) + b"\n")


def official_benchmark_problem(suite_dir: str | Path) -> str | None:
    """None when ``suite_dir`` is the official benchmark: converted (``aw-prepare official``) from
    the package whose ``benchmark.json`` has the SHA-256 the official loader pins
    (:data:`aw.official.package.BENCHMARK_SHA256`), with all of its 100 samples; else why not, in
    a phrase."""
    path = package_record_path(suite_dir)
    if not path.is_file():
        return "it was not converted from the official benchmark package (aw-prepare official PKG)"
    try:
        record = orjson.loads(path.read_bytes())
        digest, n = record["benchmark_sha256"], int(record["samples"])
    except (OSError, ValueError, TypeError, KeyError):
        return f"{path} is unreadable"
    if digest != BENCHMARK_SHA256:
        return (
            f"its package's benchmark.json (SHA-256 {str(digest)[:12]}...) is not the official benchmark's "
            f"({BENCHMARK_SHA256[:12]}...)"
        )
    if n != EXPECTED_SAMPLES:
        return f"it holds {n} of the official benchmark's {EXPECTED_SAMPLES} tasks"
    return None


_SUITE_ITEMS = ("targets", "eval_points", "official", "tasks", "manifest.json")  # manifest.json last: it makes a suite


def _existing_suite(out: Path, force: bool) -> None:
    existing = [out / n for n in _SUITE_ITEMS if (out / n).exists()]
    if existing and not force:
        raise FileExistsError(
            f"{out}: already holds a suite ({', '.join(p.name for p in existing)}); pass force=True to replace it"
        )


def _chosen_samples(pkg: OfficialPackage, samples: Iterable[tuple[str, str]] | None) -> list[tuple[str, str]]:
    """``samples`` ((block, sample id) pairs; None: every sample) in package order, after checking
    that the package holds every file they need (:class:`aw.official.errors.MissingPackageFileError`
    naming each one it lacks)."""
    listed = pkg.listed_samples()
    wanted = set(listed if samples is None else samples)
    pkg.require([key for key in listed if key in wanted], "the suite")
    blocks = {block for block, _ in wanted}
    return [(b, sid) for b in pkg.blocks if b in blocks for sid in pkg.sample_ids(b) if (b, sid) in wanted]


def _write_suite(pkg: OfficialPackage, out: Path, chosen: list[tuple[str, str]]) -> SuiteManifest:
    for sub in ("targets", "eval_points", "official"):
        (out / sub).mkdir(parents=True, exist_ok=True)
    entries = []
    for block, sid in chosen:
        tid = task_id_for_sample(block, sid)
        inputs = pkg.evaluation_inputs(block, sid)
        write_eval_inputs(eval_points_path(out, tid), inputs)
        shutil.copyfile(pkg.sample(block, sid).initial_path, initial_archive_path(out, tid))
        hint = [g for g in inputs.groups if len(g) > 1] or None
        targets = Targets(
            task_id=tid,
            parts={
                p: PartTarget(pose=[float(x) for x in pose])
                for p, pose in zip(inputs.part_ids, inputs.target_poses, strict=True)
            },
            equivalence_hint=hint,
            scale=1.0,
            eval_divisor=inputs.divisor,
        )
        write_targets(suite_paths(out, tid)[1], targets)
        b = pkg.blocks[block]
        entries.append(
            SuiteEntry(
                task_id=tid,
                source=b["source"],
                condition=REFERENCE_CONDITIONS[b["reference_mode"]],
                object_id=sid,
                category=sid.split("/")[0] if "/" in sid else "",
                n_parts=inputs.n_parts,
            )
        )
    manifest = SuiteManifest(name=f"official-{pkg.root.name}", generator="aw.official", tasks=entries)
    _write_package_record(pkg, out, len(entries))
    write_manifest(out, manifest)
    return manifest


def _commit_suite(staged: Path, out: Path) -> None:
    """Replace ``out``'s suite by the one written in ``staged``, ``manifest.json`` last."""
    for name in _SUITE_ITEMS:
        old = out / name
        if old.is_dir() and not old.is_symlink():
            shutil.rmtree(old)
        elif old.exists() or old.is_symlink():
            old.unlink()
    for name in _SUITE_ITEMS:
        if (staged / name).exists():
            os.replace(staged / name, out / name)


def convert_package(
    package: str | Path | OfficialPackage,
    suite_out: str | Path,
    force: bool = False,
    samples: Iterable[tuple[str, str]] | None = None,
) -> SuiteManifest:
    """Write the scoring suite of an official package (see the module doc): its ``samples``
    ((block, sample id) pairs, written in package order), by default every sample. Raises
    :class:`aw.official.errors.MissingPackageFileError` naming every file those samples need
    that the package lacks. The suite is written in a hidden folder of ``suite_out`` and moved
    into place once complete: a failure leaves no suite."""
    pkg = package if isinstance(package, OfficialPackage) else OfficialPackage(package, strict=False)
    chosen = _chosen_samples(pkg, samples)
    out = Path(suite_out)
    _existing_suite(out, force)
    staged = staging_dir(out, "aw-staging")
    try:
        manifest = _write_suite(pkg, staged, chosen)
        _commit_suite(staged, out)
    finally:
        shutil.rmtree(staged, ignore_errors=True)
    return manifest


def _pose_dict(part_ids: list[str], poses: np.ndarray) -> dict[str, list[float]]:
    return {p: [float(x) for x in pose] for p, pose in zip(part_ids, poses, strict=True)}


def project_camera(camera: dict[str, list[float]]) -> CameraState | None:
    """This project's orbit camera for an official ``{position, target}`` (None when it looks
    straight up or down, which the orbit camera cannot express)."""
    target = np.asarray(camera["target"], dtype=float)
    offset = target - np.asarray(camera["position"], dtype=float)
    distance = float(np.linalg.norm(offset))
    forward = offset / distance
    pitch = float(np.degrees(np.arcsin(np.clip(-forward[2], -1.0, 1.0))))
    if not abs(pitch) < 90.0:
        return None
    yaw = float(np.degrees(np.arctan2(-forward[1], -forward[0])))
    return CameraState(target=[float(x) for x in target], yaw=yaw, pitch=pitch, distance=distance)


def _call_time(call: dict) -> datetime:
    """A call's timestamp (the archive reader checked that every call's is an ISO-8601 time)."""
    moment = parse_timestamp(call["timestamp"])
    if moment is None:
        raise ValueError(f"call timestamp {call['timestamp']!r} is not an ISO-8601 time")
    return moment


def end_reason(ep: EpisodeArchive) -> tuple[EndReason, str]:
    """``(reason, message)`` of this project for an archive: an exported archive is a finished
    episode (the official browser exports ``active`` episodes); an ``ended`` one keeps its
    ``end.reason`` (and ``outcome``) as the message."""
    end = ep.end or {}
    text = " / ".join(str(end[k]) for k in ("reason", "outcome") if k in end)
    return "finished", (f"official end: {text}" if text else "")


def episode_records(ep: PartEpisode, task_id: str, system: str):
    """The project trajectory records ``(header, calls, end)`` of a restored official episode.

    Every call becomes a call line at its ``timestamp`` (seconds after the first call); a call
    that recorded a state carries that state's poses (and camera, when it moved), so writing the
    run back with :mod:`aw.official.export` gives the same state indices and vectors."""
    arc, ids, poses = ep.archive, ep.part_ids, ep.poses
    t0 = _call_time(arc.calls[0]) if arc.calls else None
    started = iso_timestamp(t0) if t0 is not None else _NO_CALLS_START
    header = TrajectoryHeader(
        task_id=task_id,
        system=system,
        started_at=started,
        part_ids=ids,
        initial_poses=_pose_dict(ids, poses[0]),
        camera=project_camera(arc.initial.record["camera"]),
    )
    calls: list[TrajectoryCall] = []
    t = 0.0
    shown = 0  # the state the previous call line left
    for call in arc.calls:
        t = max(t, (_call_time(call) - _call_time(arc.calls[0])).total_seconds())
        ok = call["status"] == "completed"
        new_states = range(max(call["before_index"], shown) + 1, call["state_index"] + 1)
        for k, index in enumerate(new_states or [None]):
            rec = {
                "seq": len(calls) + 1,
                "t": t,
                "tool": call["name"] if k == 0 else _EXTRA_STATE,
                "args": call["arguments"] if k == 0 else {},
                "ok": ok if k == 0 else True,
                "error": call.get("error") if k == 0 else None,
            }
            if index is not None:
                prev, cur = poses[shown], poses[index]
                rec["changed"] = [p for p, a, b in zip(ids, cur, prev, strict=True) if not np.array_equal(a, b)]
                rec["poses"] = _pose_dict(ids, cur)
                cam = arc.state(index).record["camera"]
                if cam != arc.state(shown).record["camera"]:
                    rec["camera"] = project_camera(cam)
                shown = index
            calls.append(TrajectoryCall(**rec))
    reason, message = end_reason(arc)
    end = TrajectoryEnd(reason=reason, t=t, message=message, poses=_pose_dict(ids, ep.final_poses()))
    return header, calls, end


def _dump(rec) -> bytes:
    return orjson.dumps(rec.model_dump(mode="json", exclude_none=True))


def write_episode_run(
    ep: PartEpisode, runs_out: str | Path, system: str, task_id: str, force: bool = False, extra: dict | None = None
) -> Path:
    """Write ``RUNS/<system>/<task_id>/`` (trajectory.jsonl, final.json, run.json) for a restored
    official episode."""
    run_dir = Path(runs_out) / system / task_id
    _free_run_dir(run_dir, force)
    try:  # never replace a recording that a live server is still writing
        lock = RunDirLock(run_dir).acquire()
    except RunDirBusy as exc:
        raise FileExistsError(str(exc)) from None
    try:
        _write_run_files(ep, run_dir, system, task_id, extra)
    finally:
        lock.release()
    return run_dir


_RUN_FILES = ("trajectory.jsonl", "final.json", "run.json")


def _free_run_dir(run_dir: Path, force: bool) -> None:
    traj = run_dir / "trajectory.jsonl"
    if traj.exists() and not force:
        raise FileExistsError(f"{traj}: already exists; pass force=True to replace it")


def _write_run_files(ep: PartEpisode, run_dir: Path, system: str, task_id: str, extra: dict | None) -> None:
    header, calls, end = episode_records(ep, task_id, system)
    run_dir.mkdir(parents=True, exist_ok=True)
    traj = run_dir / "trajectory.jsonl"
    tmp = traj.with_suffix(".jsonl.tmp")
    with open(tmp, "wb") as fh:
        for rec in [header, *calls, end]:
            fh.write(_dump(rec) + b"\n")
    os.replace(tmp, traj)
    write_final(run_dir / "final.json", FinalState(task_id=task_id, reason=end.reason, poses=end.poses))
    info = RunInfo(
        system=system,
        task_id=task_id,
        started_at=header.started_at,
        wall_seconds=end.t,
        mcp_calls=len(ep.archive.calls),
        ended="finished",
        extra={"official_archive": str(ep.path), "state_index": ep.final_index, **(extra or {})},
    )
    write_run_info(run_dir / "run.json", info)


def _commit_run(staged: Path, run_dir: Path) -> None:
    """Move a run written in ``staged`` to ``run_dir`` (its files replaced under the run's lock)."""
    run_dir.parent.mkdir(parents=True, exist_ok=True)
    try:
        lock = RunDirLock(run_dir).acquire()
    except RunDirBusy as exc:
        raise FileExistsError(str(exc)) from None
    try:
        for name in _RUN_FILES:
            os.replace(staged / name, run_dir / name)
    finally:
        lock.release()


def find_archives(root: str | Path) -> list[Path]:
    """Every ``*.episode.zip`` below ``root`` (or ``root`` itself), sorted. An archive that is a
    link leading out of ``root`` is refused, as the package reader refuses links leaving the package."""
    root = Path(root)
    if root.is_file():
        return [root]
    if not root.is_dir():
        raise FormatError(root, "episode folder not found")
    found = sorted(root.rglob("*.episode.zip"))
    inside = root.resolve()
    for path in found:
        if not path.resolve().is_relative_to(inside):
            raise FormatError(path, f"links outside the episode folder {root}")
    return found


def archive_sample(archive: Path, pkg: OfficialPackage) -> tuple[str, str]:
    """``(block, sample id)`` of an archive laid out as in a run log
    (``.../blocks/<block>/samples/<slug>/final.episode.zip``) or as ``.../<block>/<slug>.episode.zip``."""
    slug = archive.parent.name if archive.name == "final.episode.zip" else archive.name[: -len(".episode.zip")]
    block = next((p for p in reversed(archive.resolve().parts[:-1]) if p in pkg.blocks), None)
    if block is None:
        raise FormatError(archive, f"no block folder above the archive (one of {list(pkg.blocks)})")
    by_slug = {task_id_for_sample(block, sid): sid for sid in pkg.sample_ids(block)}
    sid = by_slug.get(task_id_for_sample(block, sample_id_from_slug(slug, str(archive))))
    if sid is None:
        raise FormatError(archive, f"{slug!r} is not a sample of block {block!r}")
    return block, sid


def _official_result(result: dict) -> dict:
    """What the runner's ``result.json`` says of the attempt (kept for information: the official
    scorer scores every saved archive, whatever the execution's end)."""
    found = result.get("execution")
    execution = found if isinstance(found, dict) else {}
    return {"official_status": result.get("status"), "official_execution": execution.get("status")}


def _result_beside(archive: Path) -> dict:
    path = archive.parent / "result.json"
    if archive.name != "final.episode.zip" or not path.is_file():
        return {}
    return _official_result(read_json_object(path))


def run_log_archives(
    folder: str | Path,
    pkg: OfficialPackage,
    skipped: list[str] | None = None,
    attempted: set[tuple[str, str]] | None = None,
) -> list[tuple[str, str, str, Path, dict]]:
    """``(system, block, sample id, final archive, extra)`` for every attempt that counts in the
    run logs of ``folder`` (a run folder or a ``logs/`` folder): runs are grouped by system
    (``aw.official.runlog.system_name``, as ``aw-score`` names them) and each group's attempts
    are selected as the official evaluation selects them (``aw.official.runlog.select_attempts``:
    a later attempt replaces an earlier one). Attempts the official scorer would not score (still
    running, no saved archive, archive digest differing from ``result.json``) are listed in
    ``skipped``; every selected attempt's (block, sample id), scored or not, is added to
    ``attempted``."""
    from aw.official.package import file_sha256
    from aw.official.runlog import find_runs, select_attempts, systems

    out = []
    for name, runs in systems(find_runs(folder)).items():
        for run in runs:
            pkg.check_run(run)
        try:
            attempts = select_attempts(runs)
        except ValueError as exc:
            raise FormatError(Path(folder), f"system {name}: {exc}") from None
        for (block, sid), attempt in sorted(attempts.items()):
            pkg.check_attempt(attempt)
            if attempted is not None:
                attempted.add((block, sid))
            attempt.tool_calls  # noqa: B018 - a conversation.jsonl that aw-score would refuse is refused here too
            why = (
                "the attempt is still running"
                if not attempt.finished
                else "no saved final archive"
                if not attempt.archive_saved
                else "final archive differs from result.json's sha256"
                if attempt.saved_sha256 and attempt.saved_sha256 != file_sha256(attempt.final_archive)
                else None
            )
            if why is not None:
                if skipped is not None:
                    skipped.append(f"{attempt.directory}: {why}")
                continue
            extra = {
                "block": block,
                "sample_id": sid,
                "official_run": str(attempt.run),
                **_official_result(attempt.result),
            }
            out.append((name, block, sid, attempt.final_archive, extra))
    return out


def convert(
    package: str | Path,
    episodes: str | Path | Iterable[str | Path],
    suite_out: str | Path,
    runs_out: str | Path,
    system: str | None = None,
    force: bool = False,
    skipped: list[str] | None = None,
) -> tuple[SuiteManifest, list[Path]]:
    """Convert a package and its episode archives: the counted attempts of run logs (when
    ``episodes`` is a run folder or holds run folders), else every ``*.episode.zip`` below it
    (``<block>/<slug>.episode.zip``). A run's system is ``system``, else the run log's system
    (``aw.official.runlog.system_name``), else the archive folder's name (``official`` for a list
    of archives); attempts that are not scored are listed in ``skipped``. The suite holds the
    samples attempted (those not scored too: ``aw-score`` counts them as missing, PA = SR = 0,
    as the official evaluation rows them as errors), so the package needs only their files."""
    from aw.official.runlog import archive_system, is_run_dir

    pkg = OfficialPackage(package, strict=False)
    suite, runs_root = Path(suite_out), Path(runs_out)
    _existing_suite(suite, force)
    folder, listed = (Path(episodes), []) if isinstance(episodes, (str, Path)) else (None, [Path(p) for p in episodes])
    attempted: set[tuple[str, str]] = set()
    if folder is not None and folder.is_dir() and (is_run_dir(folder) or any(is_run_dir(p) for p in folder.iterdir())):
        items = run_log_archives(folder, pkg, skipped, attempted)
    else:
        archives = find_archives(folder) if folder is not None else listed
        name = archive_system(folder) if folder is not None and folder.is_dir() else "official"
        items = []
        for arc in archives:
            block, sid = archive_sample(arc, pkg)
            items.append((name, block, sid, arc, {"block": block, "sample_id": sid, **_result_beside(arc)}))
    attempted.update((block, sid) for _, block, sid, _, _ in items)
    if not attempted:
        raise FormatError(
            folder if folder is not None else Path("."), "no attempt and no *.episode.zip archive to convert"
        )
    chosen = _chosen_samples(pkg, attempted)
    targets = [runs_root / (system or name) / task_id_for_sample(block, sid) for name, block, sid, _, _ in items]
    for k, run_dir in enumerate(targets):
        if run_dir in targets[:k]:
            raise FormatError(
                items[k][3], f"a second archive for {items[k][1]}/{items[k][2]} of system {run_dir.parent.name}"
            )
        _free_run_dir(run_dir, force)
    # Everything is read and written in hidden folders first, then moved into place: a bad archive
    # or a full disk leaves neither a suite nor runs that look complete.
    staged_suite, staged_runs = staging_dir(suite, "aw-staging"), staging_dir(runs_root, "aw-staging")
    try:
        manifest = _write_suite(pkg, staged_suite, chosen)
        for (name, block, sid, arc, extra), run_dir in zip(items, targets, strict=True):
            inputs = pkg.evaluation_inputs(block, sid)
            ep = read_part_episode(arc, pkg.initial_archive(block, sid), inputs.part_ids)
            _write_run_files(ep, staged_runs / run_dir.relative_to(runs_root), system or name, run_dir.name, extra)
        for run_dir in targets:
            _commit_run(staged_runs / run_dir.relative_to(runs_root), run_dir)
        _commit_suite(staged_suite, suite)
    finally:
        shutil.rmtree(staged_suite, ignore_errors=True)
        shutil.rmtree(staged_runs, ignore_errors=True)
    runs = targets
    return manifest, runs
