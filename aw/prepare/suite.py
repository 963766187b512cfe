"""Building a whole suite: many objects, in parallel worker processes, then one manifest.

An object is described by an :class:`ObjectSpec`: the dotted name of a loader function and its
arguments (so a worker process can rebuild it; nothing heavy is pickled), the conditions to
build, and optionally a donor object for the distractor variant. Task files are written by the
workers; the manifest lists the tasks in spec order, so the suite does not depend on the number
of workers or on which finished first.
"""

from __future__ import annotations

import importlib
import multiprocessing
import os
import shutil
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from aw.assembly import AssembledObject
from aw.cores import available_cores
from aw.formats import SuiteEntry, SuiteManifest, write_manifest
from aw.formats.io import staging_dir
from aw.prepare.build import VariantPlan, prepare_object
from aw.prepare.geometry import part_size_ratio
from aw.prepare.references import IMAGE_SIZE, MANUAL_SIZE

__all__ = [
    "ObjectError",
    "ObjectSpec",
    "ObjectResult",
    "build_suite",
    "prepare_output_dir",
    "summarize",
    "format_summary",
    "SuiteExistsError",
]


class ObjectError(RuntimeError):
    """Preparing one object failed; the message names the object and the cause."""


class SuiteExistsError(FileExistsError):
    """The output directory already holds a suite and overwriting was not asked for."""


@dataclass(frozen=True)
class ObjectSpec:
    """How to obtain one assembled object: ``loader`` is ``"package.module:function"``,
    called as ``function(*args)`` and returning an :class:`AssembledObject`."""

    loader: str
    args: tuple = ()
    conditions: tuple[str, ...] = ("none",)
    donor: ObjectSpec | None = None

    def load(self) -> AssembledObject:
        module, _, name = self.loader.partition(":")
        fn = getattr(importlib.import_module(module), name)
        obj = fn(*self.args)
        if not isinstance(obj, AssembledObject):
            raise TypeError(f"{self.loader} returned {type(obj).__name__}, not an AssembledObject")
        return obj


@dataclass
class ObjectResult:
    """Per object: its manifest entries and the figures of the summary."""

    index: int
    object_id: str
    source: str
    category: str
    n_parts: int
    size_ratio: float
    entries: list[SuiteEntry] = field(default_factory=list)


@dataclass(frozen=True)
class _Settings:
    suite_dir: str
    seed: int
    variants: VariantPlan | None
    image_size: tuple[int, int]
    manual_size: tuple[int, int]
    protocol: str = "native"


def _build_one(index: int, spec: ObjectSpec, settings: _Settings) -> ObjectResult:
    # Errors travel back from worker processes as ObjectError (plain message): exceptions
    # with custom constructors such as FormatError do not survive pickling.
    try:
        obj = spec.load()
    except Exception as exc:
        raise ObjectError(f"loading {spec.loader}{spec.args}: {exc}") from None
    try:
        donor = spec.donor.load() if spec.donor is not None and settings.variants is not None else None
        entries = prepare_object(
            obj,
            settings.suite_dir,
            spec.conditions,
            settings.seed,
            variants=settings.variants,
            donor=donor,
            image_size=settings.image_size,
            manual_size=settings.manual_size,
            protocol=settings.protocol,
        )
    except Exception as exc:
        raise ObjectError(f"object {obj.source}/{obj.object_id}: {type(exc).__name__}: {exc}") from None
    return ObjectResult(
        index,
        obj.object_id,
        obj.source,
        obj.category,
        obj.n_parts,
        part_size_ratio([p.mesh for p in obj.parts]),
        entries,
    )


# What a suite consists of in its directory; the manifest last, so that a suite is complete once it appears.
SUITE_ENTRIES = ("tasks", "targets", "eval_points", "manifest.json")


def _existing_suite(out: Path, force: bool) -> list[Path]:
    """The suite entries already in ``out``; an error if there are any and not ``force``."""
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"{out}: exists and is not a directory")
    existing = [out / n for n in SUITE_ENTRIES if (out / n).exists()]
    if existing and not force:
        raise SuiteExistsError(
            f"{out}: already holds a suite ({', '.join(p.name for p in existing)}); pass --overwrite to replace it"
        )
    return existing


def prepare_output_dir(out: str | Path, force: bool = False) -> Path:
    """Create ``out`` for a new suite. An existing suite there (``manifest.json``, ``tasks/``,
    ``targets/`` or ``eval_points/``) is an error unless ``force``, which removes exactly those."""
    out = Path(out)
    for p in _existing_suite(out, force):
        shutil.rmtree(p) if p.is_dir() else p.unlink()
    (out / "tasks").mkdir(parents=True, exist_ok=True)
    (out / "targets").mkdir(parents=True, exist_ok=True)
    return out


def build_suite(
    specs: Sequence[ObjectSpec],
    out: str | Path,
    *,
    name: str,
    generator: str = "",
    seed: int = 0,
    variants: VariantPlan | Sequence[VariantPlan | None] | None = None,
    jobs: int | None = None,
    force: bool = False,
    progress: bool = True,
    image_size: tuple[int, int] = IMAGE_SIZE,
    manual_size: tuple[int, int] = MANUAL_SIZE,
    protocol: str = "native",
) -> tuple[SuiteManifest, list[ObjectResult]]:
    """Prepare every object of ``specs`` into the suite ``out`` and write its manifest.

    ``variants``: one plan for all objects, or one (or None) per spec. ``jobs``: worker
    processes (1: in this process). ``protocol``: ``native`` or ``official`` (see
    :func:`aw.prepare.prepare_object`). Rendering picks its GL platform before workers start.
    """
    if not specs:
        raise ValueError("no objects to prepare")
    out = Path(out)
    _existing_suite(out, force)  # refused before any work
    created = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    # Built in a hidden folder inside ``out`` and moved into place whole: a failure or Ctrl-C
    # leaves no partial suite (nor half of a replaced one), and the same command can be rerun.
    stage = staging_dir(out, "partial-suite")  # also removes those a killed build left
    try:
        manifest, done = _build_into(
            specs,
            prepare_output_dir(stage),
            name=name,
            generator=generator,
            seed=seed,
            variants=variants,
            jobs=jobs,
            progress=progress,
            image_size=image_size,
            manual_size=manual_size,
            protocol=protocol,
        )
        replaced = stage / ".replaced"
        replaced.mkdir()
        for p in reversed([out / n for n in SUITE_ENTRIES]):  # the old suite out of the way, manifest first
            if p.exists():
                os.replace(p, replaced / p.name)
        for n in SUITE_ENTRIES:  # renames within one file system; the manifest last
            if (stage / n).exists():
                os.replace(stage / n, out / n)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
        if created and not any(out.iterdir()):
            out.rmdir()
    return manifest, done


def _build_into(
    specs, out: Path, *, name, generator, seed, variants, jobs, progress, image_size, manual_size, protocol
) -> tuple[SuiteManifest, list[ObjectResult]]:
    """:func:`build_suite`'s work, written into the empty suite folder ``out``."""
    plans = list(variants) if isinstance(variants, Sequence) else [variants] * len(specs)
    if len(plans) != len(specs):
        raise ValueError("variants must be one plan or one per spec")
    settings = [_Settings(str(out), seed, plan, tuple(image_size), tuple(manual_size), protocol) for plan in plans]
    jobs = available_cores() if jobs is None else max(1, int(jobs))
    needs_render = any(c != "none" for s in specs for c in s.conditions)
    if needs_render:
        from aw.render_platform import select_platform

        select_platform()  # sets PYOPENGL_PLATFORM once; workers inherit it

    results: list[ObjectResult | None] = [None] * len(specs)
    bar = _progress(len(specs), progress)
    try:
        if jobs == 1 or len(specs) == 1:
            for i, spec in enumerate(specs):
                results[i] = _build_one(i, spec, settings[i])
                bar.update(1)
        else:
            ctx = multiprocessing.get_context("spawn")
            with ProcessPoolExecutor(max_workers=min(jobs, len(specs)), mp_context=ctx) as pool:
                futures = {pool.submit(_build_one, i, spec, settings[i]): i for i, spec in enumerate(specs)}
                try:
                    for fut in as_completed(futures):
                        results[futures[fut]] = fut.result()
                        bar.update(1)
                except BaseException:
                    # first failure (or Ctrl-C): drop the queued objects instead of building them
                    pool.shutdown(wait=True, cancel_futures=True)
                    raise
    finally:
        bar.close()

    done = [r for r in results if r is not None]
    entries = [e for r in done for e in r.entries]
    manifest = SuiteManifest(name=name, generator=generator, seed=seed, tasks=entries)
    write_manifest(out, manifest)
    return manifest, done


def _progress(total: int, enabled: bool):
    from aw.progress import progress

    return progress(total, "preparing objects", "obj", enabled=enabled, leave=False)


def _band(n: int) -> str:
    return "2-5" if n <= 5 else "6-10" if n <= 10 else "11-20" if n <= 20 else ">20"


def summarize(manifest: SuiteManifest, results: Sequence[ObjectResult]) -> dict[str, dict[str, Any]]:
    """Per source: objects, tasks (by condition and variant), part counts and part-size ratios."""
    out: dict[str, dict[str, Any]] = {}
    for source in dict.fromkeys(r.source for r in results):
        objs = [r for r in results if r.source == source]
        tasks = [t for t in manifest.tasks if t.source == source]
        counts = np.array([r.n_parts for r in objs])
        ratios = np.array([r.size_ratio for r in objs])
        bands = {b: int(sum(_band(n) == b for n in counts)) for b in ("2-5", "6-10", "11-20", ">20")}
        out[source] = {
            "objects": len(objs),
            "tasks": len(tasks),
            "conditions": {c: sum(t.condition == c for t in tasks) for c in dict.fromkeys(t.condition for t in tasks)},
            "variants": {v: sum(t.variant == v for t in tasks) for v in dict.fromkeys(t.variant for t in tasks)},
            "categories": {c: sum(r.category == c for r in objs) for c in sorted({r.category for r in objs})},
            "parts_total": int(counts.sum()),
            "parts_min": int(counts.min()),
            "parts_median": float(np.median(counts)),
            "parts_max": int(counts.max()),
            "part_bands": {b: v for b, v in bands.items() if v or b != ">20"},
            "part_counts": sorted(int(c) for c in counts),
            "size_ratio_median": float(np.median(ratios)),
            "size_ratio_q1": float(np.percentile(ratios, 25)),
            "size_ratio_q3": float(np.percentile(ratios, 75)),
            "size_ratio_p90": float(np.percentile(ratios, 90)),
        }
    return out


def format_summary(summary: dict[str, dict[str, Any]]) -> str:
    """A plain-text table of :func:`summarize` output."""
    head = ("source", "objects", "tasks", "parts min/med/max", "bands 2-5/6-10/11-20", "size ratio median [IQR]")
    rows = []
    for source, s in summary.items():
        b = s["part_bands"]
        rows.append(
            (
                source,
                str(s["objects"]),
                str(s["tasks"]),
                f"{s['parts_min']}/{s['parts_median']:g}/{s['parts_max']}",
                f"{b['2-5']}/{b['6-10']}/{b['11-20']}",
                f"{s['size_ratio_median']:.2f} [{s['size_ratio_q1']:.2f}-{s['size_ratio_q3']:.2f}]",
            )
        )
    rows.append(
        (
            "total",
            str(sum(s["objects"] for s in summary.values())),
            str(sum(s["tasks"] for s in summary.values())),
            "",
            "",
            "",
        )
    )
    widths = [max(len(r[k]) for r in [head, *rows]) for k in range(len(head))]

    def fmt(r):
        return "  ".join(
            c.ljust(w) if k in (0, 3, 4, 5) else c.rjust(w) for k, (c, w) in enumerate(zip(r, widths))
        ).rstrip()

    rule = "-" * len(fmt(head))
    lines = [fmt(head), rule, *(fmt(r) for r in rows[:-1]), rule, fmt(rows[-1])]
    for source, s in summary.items():
        conds = ", ".join(f"{k} {v}" for k, v in s["conditions"].items())
        cats = ", ".join(f"{k or '(no category)'} {v}" for k, v in s["categories"].items())
        variants = ", ".join(f"{k} {v}" for k, v in s["variants"].items())
        lines.append(
            f"{source}: conditions {conds}; variants {variants}; categories {cats}; part counts {s['part_counts']}"
        )
    return "\n".join(lines)
