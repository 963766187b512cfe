"""The study's only contact with the evaluator core (``aw_eval``'s public API).

Keeping every call here makes the batch front end independent of the evaluator's internals:
``load_geometry`` (cached per task), ``score_states`` (a batch of checkpoints in one call) and
``final_diagnostics`` (centred CDs and centroid offsets under the saved registration and
matching, for the failure classes).
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "prepare_thread",
    "protocol_settings",
    "load_geometry",
    "batched_backend",
    "prescore",
    "score_states",
    "final_diagnostics",
    "evaluator_version",
    "MODES",
    "BACKENDS",
]

MODES = ("exact", "fast")
BACKENDS = ("auto", "numba", "jax")  # aw_eval.registration.BACKENDS, without importing aw_eval here


@functools.lru_cache(maxsize=1)
def evaluator_version() -> str:
    """Version of the scoring code; part of every cache key: the evaluator's ``__version__`` and
    a hash of the source of every module that computes cached numbers (the evaluator core, this
    package's scoring modules, the trajectory reader), so that any change to them rescores."""
    import hashlib

    import aw.formats.trajectory
    import aw_eval

    core = Path(aw_eval.__file__).parent
    files = sorted(p for p in core.glob("*.py") if p.name not in ("cli.py", "__init__.py"))
    files += sorted((core / "kernels").glob("*.py"))
    files += [core / "study" / f for f in ("episode.py", "job.py", "decreases.py", "evaluator.py", "model.py")]
    files.append(Path(aw.formats.trajectory.__file__))
    h = hashlib.sha256()
    for f in files:
        h.update(f.name.encode() + b"\0" + f.read_bytes())
    return f"{getattr(aw_eval, '__version__', '0')}+src{h.hexdigest()[:12]}"


def prepare_thread() -> None:
    """Per-thread setup before scoring in this thread: loads the compiled kernels (numba's
    on-disk cache) up front, so the first checkpoint's timing is not a compile."""
    from aw_eval.kernels import compile_kernels

    compile_kernels()


def protocol_settings(overrides=()):
    """``ProtocolSettings`` with ``overrides`` ((name, value) pairs) applied; None without any.
    Unknown names or invalid values raise ``ValueError``."""
    if not overrides:
        return None
    from aw_eval.settings import ProtocolSettings

    fields = ProtocolSettings.__dataclass_fields__
    kw = {}
    for name, value in overrides:
        if name not in fields:
            raise ValueError(f"unknown protocol setting {name!r}; known: {', '.join(fields)}")
        kw[name] = int(value) if fields[name].type in (int, "int") else float(value)
    return ProtocolSettings(**kw)


def load_geometry(task_dir: Path, targets_path: Path, cache_dir: Path | None, overrides=()):
    import aw_eval

    settings = protocol_settings(overrides)
    if settings is None:
        return aw_eval.load_task_geometry(task_dir, targets_path, cache_dir=cache_dir)
    return aw_eval.load_task_geometry(task_dir, targets_path, cache_dir=cache_dir, settings=settings)


def batched_backend(mode: str, backend: str) -> bool:
    """True where ``mode`` scores on the jax backend: a task's runs are then scored together
    (:func:`prescore`), so that every call fills the device with checkpoints of all of them."""
    from aw_eval.registration import resolve_backend

    return mode == "exact" and resolve_backend(backend, mode) == "jax"


def prescore(geom, poses: list[np.ndarray], mode: str, backend: str) -> dict[bytes, Any]:
    """Every distinct state of the ``(N_i, P, 7)`` arrays of ``poses`` (a task's runs) scored in
    one batch; returns the memo :func:`score_states` takes (state bytes -> its scores)."""
    import aw_eval

    rows = [np.asarray(p, dtype=np.float64).reshape(-1, geom.n_parts, 7) for p in poses]
    allp = np.concatenate(rows) if rows else np.zeros((0, geom.n_parts, 7))
    if len(allp) == 0:
        return {}
    allp = np.unique(allp, axis=0)
    b = aw_eval.score_batch(geom, allp, mode=mode, backend=backend)
    return {allp[i].tobytes(): b.row(i) for i in range(len(allp))}


def score_states(geom, poses: np.ndarray, mode: str, backend: str = "auto", memo: dict | None = None) -> dict[str, Any]:
    """Scores of ``poses: (N, P, 7)``: ``part_errors (N, P)``, ``assignment (N, P)``, ``pa``,
    ``sr``, ``sra``, ``scd`` ``(N,)`` and the raw batch result under ``"batch"``. ``backend``
    applies to ``exact`` (``fast`` always runs on the CPU kernels). ``memo``: states already
    scored in this mode (:func:`prescore`); rows found there are not scored again."""
    import aw_eval
    from aw_eval.results import BatchScores

    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    poses = np.asarray(poses, dtype=np.float64)
    if memo and len(poses) and all(geom.check_poses(p).tobytes() in memo for p in poses):
        found = [memo[geom.check_poses(p).tobytes()] for p in poses]
        b = BatchScores.stack(found, mode, len({p.tobytes() for p in poses}))
    else:
        b = aw_eval.score_batch(geom, poses, mode=mode, backend=backend if mode == "exact" else "numba")
    return {
        "part_errors": np.asarray(b.part_errors, dtype=np.float64),
        "assignment": np.asarray(b.assignment, dtype=np.int64),
        "pa": np.asarray(b.pa, dtype=np.float64),
        "sr": np.asarray(b.sr, dtype=np.float64),
        "sra": np.asarray(b.sra, dtype=np.float64),
        "scd": np.asarray(b.scd, dtype=np.float64),
        "reg_rotation": np.asarray(b.reg_rotation, dtype=np.float64),
        "reg_translation": np.asarray(b.reg_translation, dtype=np.float64),
        "batch": b,
    }


def final_diagnostics(geom, poses: np.ndarray, scores: dict[str, Any], row: int) -> tuple[np.ndarray, np.ndarray]:
    """``(centred_cd (P,), offset (P,))`` of row ``row`` of a scored batch."""
    import aw_eval

    d = aw_eval.part_diagnostics(geom, poses[row], scores["batch"], row)
    return np.asarray(d.centred_cd, dtype=np.float64), np.asarray(d.offset, dtype=np.float64)
