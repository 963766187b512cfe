"""Writing one prepared task: ``tasks/<id>/`` (public) and ``targets/<id>.json`` (hidden)."""

from __future__ import annotations

import io
import re
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from PIL import Image

from aw.formats import (
    CONDITIONS,
    Condition,
    FormatError,
    PartTarget,
    SuiteEntry,
    Targets,
    Task,
    TaskPart,
    write_targets,
    write_task,
)
from aw.formats.suite import suite_paths
from aw.formats.targets import Variant
from aw.prepare.objfile import write_obj
from aw.prepare.standardize import PreparedObject
from aw.prompt import task_prompt

__all__ = ["safe_id", "task_id_for", "write_prepared", "png_bytes"]

_UNSAFE = re.compile(r"[^A-Za-z0-9_.-]+")


def safe_id(text: str) -> str:
    """``text`` reduced to the characters a task id may hold (others become ``_``)."""
    out = _UNSAFE.sub("_", str(text)).strip("_.") or "object"
    return out[:100]


def task_id_for(source: str, object_id: str, condition: str, variant: str = "") -> str:
    """``<source>-<object>-<condition>[-<variant>]``, e.g. ``partnet-chair_007-image-missing``."""
    parts = [safe_id(source), safe_id(object_id), condition] + ([safe_id(variant)] if variant else [])
    return "-".join(parts)


def png_bytes(ref: Any) -> bytes:
    """A reference (``PIL.Image`` or image file path) as PNG bytes; PNG files are copied as is."""
    if isinstance(ref, Image.Image):
        buf = io.BytesIO()
        ref.save(buf, format="PNG", optimize=False)
        return buf.getvalue()
    path = Path(ref)
    if not path.is_file():
        raise FormatError(path, "reference image not found")
    data = path.read_bytes()
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        return data
    try:
        with Image.open(io.BytesIO(data)) as im:
            im.load()
            return png_bytes(im.convert("RGBA" if im.mode in ("RGBA", "LA", "P") else "RGB"))
    except Exception as exc:  # PIL raises many types for broken files
        raise FormatError(path, f"cannot be read as an image ({type(exc).__name__})") from None


def write_prepared(
    prep: PreparedObject,
    suite_dir: str | Path,
    task_id: str,
    condition: Condition,
    references: Sequence[Any] = (),
    base_task_id: str | None = None,
    weight: float = 1.0,
) -> SuiteEntry:
    """Write the task directory and hidden targets of ``prep`` under ``suite_dir``.

    ``references``: images in order (``PIL.Image`` or file paths), written as
    ``references/01.png, 02.png, ...``. An existing task directory of that id is replaced.
    """
    if condition not in CONDITIONS:  # a caller's unchecked string
        raise ValueError(f"condition must be none, image or manual, got {condition!r}")
    if condition == "none" and references:
        raise ValueError("a task with condition 'none' takes no references")
    if condition != "none" and not references:
        raise ValueError(f"condition {condition!r} needs at least one reference image")
    obj = prep.obj
    task_dir, targets_path = suite_paths(suite_dir, task_id)
    if task_dir.exists():
        shutil.rmtree(task_dir)
    (task_dir / "parts").mkdir(parents=True)

    for part in prep.parts:
        write_obj(task_dir / "parts" / f"{part.part_id}.obj", part.mesh)
    ref_names = []
    if references:
        (task_dir / "references").mkdir()
        for k, ref in enumerate(references, start=1):
            name = f"references/{k:02d}.png"
            (task_dir / name).write_bytes(png_bytes(ref))
            ref_names.append(name)

    task = Task(
        task_id=task_id,
        source=obj.source,
        dataset=obj.dataset,
        category=obj.category,
        object_id=obj.object_id,
        condition=condition,
        prompt=task_prompt(condition),
        parts=[TaskPart(id=p.part_id, mesh=f"parts/{p.part_id}.obj") for p in prep.parts],
        references=ref_names,
    )
    write_task(task_dir, task)

    variant = dict(prep.variant)
    kind = variant.pop("kind", "original")
    targets = Targets(
        task_id=task_id,
        parts={
            p.part_id: PartTarget(pose=[float(x) for x in p.target], source_name=p.source_name, distractor=p.distractor)
            for p in prep.parts
        },
        equivalence_hint=prep.equivalence_hint,
        scale=prep.scale,
        eval_divisor=prep.eval_divisor,
        seed=prep.seed,
        variant=Variant(kind=kind, base_task_id=base_task_id if kind != "original" else None, **variant),
    )
    write_targets(targets_path, targets)
    return SuiteEntry(
        task_id=task_id,
        source=obj.source,
        condition=condition,
        object_id=obj.object_id,
        category=obj.category,
        n_parts=len(prep.parts),
        weight=weight,
        variant=kind,
        base_task_id=base_task_id if kind != "original" else None,
    )
