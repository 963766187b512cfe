"""Official-layout episodes for the tests, made by this project's own writers
(:mod:`aw.official.world`, :mod:`aw.official.archive`): a setup archive of small boxes, and an
active episode recorded the way the official runtime records one (calls with ISO timestamps,
a state per successful edit, input/final/rollback traces after the states)."""

from __future__ import annotations

import copy
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np

from aw.official.archive import EpisodeArchive, Frame, iso_timestamp, write_archive
from aw.official.episode import load_model
from aw.official.world import PRODUCER, append_state, setup_archive

PART_IDS = ["0", "1", "2"]
T0 = datetime(2026, 1, 2, 3, 4, 5, 678000, tzinfo=UTC)


def box(half: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices (8, 3), faces (12, 3))`` of an axis-aligned box centred at the origin."""
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
    faces = np.array(
        [
            [0, 1, 3],
            [0, 3, 2],
            [4, 6, 7],
            [4, 7, 5],
            [0, 4, 5],
            [0, 5, 1],
            [2, 3, 7],
            [2, 7, 6],
            [0, 2, 6],
            [0, 6, 4],
            [1, 5, 7],
            [1, 7, 3],
        ]
    )
    return signs * np.asarray(half), faces


MESHES = [box((0.1, 0.2, 0.3)), box((0.05, 0.05, 0.4)), box((0.2, 0.1, 0.1))]
INITIAL = np.array([[0.5, 0.0, 0.1, 1, 0, 0, 0], [-0.4, 0.3, 0.0, 0, 1, 0, 0], [0.0, -0.6, 0.2, 0.5, 0.5, 0.5, 0.5]])
FINAL = np.array(
    [[0.0, 0.0, 0.0, 1, 0, 0, 0], [0.0, 0.0, 0.5, 1, 0, 0, 0], [0.3, 0.0, 0.0, 0.70710678, 0, 0.70710678, 0]]
)


def write_setup(path: Path, part_ids: list[str] = PART_IDS) -> EpisodeArchive:
    ep = setup_archive(
        part_ids,
        MESHES[: len(part_ids)],
        INITIAL[: len(part_ids)],
        name=f"fixture / {path.stem}",
        task="Assemble the parts.",
    )
    return write_archive(ep, path)


class Recorder:
    """Records calls on a copy of a setup archive as the official runtime does."""

    def __init__(self, setup: EpisodeArchive):
        self.ep = EpisodeArchive(setup.path, copy.deepcopy(setup.manifest), dict(setup.files), setup.initial)
        self.model = load_model(self.ep)
        self.clock = T0

    def _call(self, name: str, arguments: dict, *, error: str | None = None) -> dict:
        ep = self.ep
        if ep.manifest["lifecycle"] == "setup":
            ep.manifest["lifecycle"] = "active"
            ep.manifest["originTime"] = float(ep.initial.integration[0])
        self.clock += timedelta(seconds=1.5)
        n = len(ep.calls)
        call = {
            "index": n,
            "id": f"call-{n}",
            "name": name,
            "arguments": arguments,
            "actor": "agent",
            "producer": dict(PRODUCER),
            "timestamp": iso_timestamp(self.clock),
            "before_index": len(ep.states),
            "state_index": len(ep.states),
            "trace_start": len(ep.traces),
            "trace_end": len(ep.traces),
            "sim_start": 0.0,
            "sim_end": 0.0,
            "steps": 0,
            "status": "completed",
        }
        ep.calls.append(call)
        return call

    def _trace(self, call: dict, phase: str, frame: Frame) -> None:
        rec = dict(frame.record, index=len(self.ep.traces), call_id=call["id"], phase=phase, step=0, sim_time=0.0)
        self.ep.traces.append(Frame("trace", rec, frame.integration.copy()))
        call["trace_end"] = len(self.ep.traces)

    def _events(self, call: dict) -> None:
        for kind in ("request", "complete"):
            self.ep.events.append(
                {
                    "index": len(self.ep.events),
                    "call_id": call["id"],
                    "kind": kind,
                    "timestamp": call["timestamp"],
                    "sim_time": 0.0,
                }
            )

    def query(self, name: str = "get_state") -> None:
        call = self._call(name, {})
        call["result"] = {"status": "active"} if name == "start_episode" else {}
        self._events(call)

    def move(self, k: int, pose: np.ndarray) -> None:
        call = self._call(
            "set_object_pose", {"id": f"part-{k + 1:04d}", "position": list(pose[:3]), "quaternion": list(pose[3:])}
        )
        before = self.ep.final_state()
        self._trace(call, "input", before)
        frame = append_state(self.model, self.ep, {k: np.asarray(pose, float)})
        self._trace(call, "final", frame)
        call["state_index"] = frame.index
        call["result"] = {"status": "completed", "index": frame.index}
        self._events(call)

    def fail(self) -> None:
        call = self._call("translate_objects", {"ids": ["nope"], "delta": [1, 0, 0]}, error="Unknown object: nope")
        call.update(status="error", error="Unknown object: nope", error_code="invalid_argument")
        self._trace(call, "rollback", self.ep.final_state())
        self._events(call)

    def cancel(self, k: int, pose: np.ndarray, steps: int = 3) -> None:
        """A last call cancelled as the page was exported: ``steps`` physics traces moving part
        ``k`` towards ``pose`` after the last state, no new state, and no events for it."""
        call = self._call("advance_simulation", {"duration": 1.0})
        call.update(
            status="error",
            error="Operation cancelled.",
            error_code="cancelled",
            cancellation={"phase": "physics", "step": steps},
            steps=steps,
        )
        moving = append_state(self.model, self.ep, {k: np.asarray(pose, float)})
        self.ep.states.pop()  # the motion only reaches the trace rows
        for step in range(1, steps + 1):
            self._trace(call, "physics", moving)
            self.ep.traces[-1].record["step"] = step

    def save(self, path: Path) -> EpisodeArchive:
        return write_archive(self.ep, path)


def write_active(setup: EpisodeArchive, path: Path, final: np.ndarray = FINAL) -> EpisodeArchive:
    """start_episode, a query, one move per part ending at ``final``, a failed call, a query."""
    rec = Recorder(setup)
    rec.query("start_episode")
    rec.query("get_state")
    for k, pose in enumerate(final[: len(setup.manifest["objects"])]):
        rec.move(k, pose)
    rec.fail()
    rec.query("list_objects")
    return rec.save(path)


# --- a benchmark package ----------------------------------------------------------------------

PACKAGE_SAMPLES = {
    "partnet-none": ["21905", "743"],
    "partnet-final-image": ["21905", "743"],
    "ikea-manualbook": ["Chair/reidar"],
}
SOURCES = {"partnet-none": "partnet", "partnet-final-image": "partnet", "ikea-manualbook": "ikea-manualbook"}
REPOS = {
    "partnet-none": "AssemblyWorld/partnet-manualpa",
    "partnet-final-image": "AssemblyWorld/partnet-manualpa",
    "ikea-manualbook": "AssemblyWorld/ikea-manual",
}
MODES = {"partnet-none": "none", "partnet-final-image": "final-image", "ikea-manualbook": "manualbook"}
DIVISOR = 0.7


def evaluation_points(seed: int = 12) -> np.ndarray:
    """``(3, 1000, 3)`` points inside each fixture box (body frame)."""
    rng = np.random.default_rng(seed)
    return np.stack([rng.uniform(-1, 1, size=(1000, 3)) * np.ptp(v, axis=0) / 2 for v, _ in MESHES])


def write_package(root: Path, samples: dict[str, list[str]] = PACKAGE_SAMPLES) -> Path:
    """An official-layout package of the fixture parts (``strict=False``: some blocks only)."""
    import hashlib

    from aw.official.evaluation_cache import (
        EVALUATION_PROTOCOL,
        PREPARATION_PROTOCOL,
        EvaluationInputs,
        similarity_protocol,
        write_evaluation,
        write_json,
    )
    from aw.official.ids import sample_slug

    def sha(data: bytes) -> str:
        return hashlib.sha256(data).hexdigest()

    blocks = []
    points = evaluation_points()
    for name, ids in samples.items():
        repo, revision = REPOS[name], "a" * 40
        identity = {"dataset": repo, "revision": revision, "protocol": PREPARATION_PROTOCOL}
        folder = root / name / repo.split("/")[-1] / "prep-v1-s0-i0-fixture"
        entries = {}
        for sid in ids:
            slug = sample_slug(sid)
            setup = write_setup(folder / f"{slug}.episode.zip")
            data = setup.path.read_bytes()
            entries[sid] = {
                "episode": f"{slug}.episode.zip",
                "episode_id": setup.manifest["id"],
                "sha256": sha(data),
                "parts": 3,
            }
            key = {
                "sample_id": sid,
                "identity": identity,
                "initial_sha256": sha(data),
                "parts": 3,
                "preparation_protocol": PREPARATION_PROTOCOL,
                "evaluation_protocol": EVALUATION_PROTOCOL,
                "similarity": similarity_protocol(),
            }
            write_evaluation(
                folder / "cache" / slug / "evaluation.json",
                EvaluationInputs(
                    sid,
                    PART_IDS,
                    points,
                    FINAL,
                    DIVISOR,
                    [["0"], ["1"], ["2"]],
                    key,
                    {"policy": "geometry"},
                    {"created_at": "2026-01-01T00:00:00+00:00", "code_commit": None, "dataset": repo},
                ),
            )
            if MODES[name] != "none":
                refdir = folder / "cache" / slug / "reference" / MODES[name]
                refdir.mkdir(parents=True, exist_ok=True)
                pages = []
                for page in (1, 2):
                    image = b"\x89PNG\r\n\x1a\n" + bytes([page]) * 32
                    (refdir / f"{page}.png").write_bytes(image)
                    pages.append({"page": page, "file": f"{page}.png", "source_sha256": sha(image)})
                write_json(
                    refdir / "pages.json",
                    {"dataset": repo, "revision": revision, "reference_mode": MODES[name], "pages": pages},
                )
        write_json(
            folder / "config.json",
            {"version": 1, "config_id": "prep-v1-s0-i0-fixture", "identity": identity, "samples": entries},
        )
        task = f"Assemble the parts ({name}).".encode()
        (root / name / "task.txt").write_bytes(task)
        blocks.append(
            {
                "name": name,
                "source": SOURCES[name],
                "repo_id": repo,
                "revision": revision,
                "config_id": "prep-v1-s0-i0-fixture",
                "data": name,
                "samples": entries,
                "reference_mode": MODES[name],
                "prompt_file": f"{name}/task.txt",
                "prompt_sha256": sha(task),
            }
        )
    write_json(
        root / "benchmark.json",
        {
            "version": 1,
            "blocks": blocks,
            "sources": sorted(set(SOURCES.values())),
            "evaluation": {
                "protocol": "assembly-evaluation-v1",
                "similarity_policy": "geometry",
                "similarity_threshold": 0.0001,
            },
        },
    )
    return root


def write_run_log(
    logs: Path,
    pkg,
    finals: dict[tuple[str, str], np.ndarray | None],
    run_id: str,
    source_run: Path | None = None,
    status: str = "completed",
) -> Path:
    """A run of the official runner's layout (``aw.official.runlog``) over ``pkg``: each
    (block, sample id) of ``finals`` gets a final archive reaching those poses (None: a failed
    attempt without an export)."""
    from aw.official.runlog import create_run, write_result

    selection: dict[str, list[str]] = {}
    for block, sid in finals:
        selection.setdefault(block, []).append(sid)
    inputs = {}
    for block, sid in finals:
        sample = pkg.sample(block, sid)
        inputs[(block, sid)] = {
            **sample.expected,
            "initial_path": str(sample.initial_path),
            "initial_calls": 0,
            "identity": pkg.configuration(block)[1]["identity"],
            "reference": sample.reference,
        }
    run = create_run(
        logs,
        selection,
        inputs,
        {b: pkg.task_text(b) for b in selection},
        {b: pkg.blocks[b]["reference_mode"] for b in selection},
        {"agent": "fixture", "model": "m"},
        source_run=source_run,
        run_id=run_id,
    )
    for (block, sid), final in finals.items():
        if final is None:
            write_result(run, block, sid, {"status": "failed", "execution": {"status": "failed"}})
            continue
        path = run.sample_dir(block, sid) / "staged.episode.zip"
        arc = write_active(pkg.initial_archive(block, sid), path, final=final)
        data = path.read_bytes()
        path.unlink()
        write_result(
            run,
            block,
            sid,
            {"status": status, "execution": {"status": "completed"}},
            final_archive=data,
            archive_calls=len(arc.calls),
        )
    return run.path
