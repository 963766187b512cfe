"""One Inspect sample per suite task.

A sample's input is one user message: the task text that ``aw-serve TASK_DIR --print-prompt``
prints (``task.json``'s ``prompt``, the paper's Appendix A.2 text), followed under the image and
manual conditions by the task's reference images as image content, in the paper's order. Its
metadata is what the Overall metric (eq. 3) needs: source, condition, object id and weight. No
hidden data (targets, target poses) goes into a sample.
"""

from __future__ import annotations

import base64
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from inspect_ai.dataset import MemoryDataset, Sample
from inspect_ai.model import ChatMessage, ChatMessageUser, Content, ContentImage, ContentText

from aw.formats import read_manifest, read_task
from aw.formats.suite import SuiteEntry, suite_paths

__all__ = ["task_filter", "suite_samples", "sample_input", "entry_metadata"]

_MIME = {".png": "image/png", ".jpg": "image/jpeg", ".jpeg": "image/jpeg"}


def task_filter(tasks: str | Sequence[str] | None) -> list[str] | None:
    """The task ids of the ``tasks`` argument: a comma-separated string or a list (None: all)."""
    if tasks is None:
        return None
    items = tasks.split(",") if isinstance(tasks, str) else [str(t) for t in tasks]
    wanted = [t.strip() for t in items if t.strip()]
    return wanted or None


def _image(path: Path) -> ContentImage:
    mime = _MIME.get(path.suffix.lower())
    if mime is None:
        raise ValueError(f"{path}: reference images must be PNG or JPEG")
    return ContentImage(image=f"data:{mime};base64,{base64.b64encode(path.read_bytes()).decode('ascii')}")


def sample_input(task_dir: Path) -> list[ChatMessage]:
    """The user message of a task: its prompt, then its reference images (if any), in order."""
    task = read_task(task_dir)
    content: list[Content] = [ContentText(text=task.prompt)]
    content += [_image(p) for p in task.reference_paths()]
    return [ChatMessageUser(content=content)]


def entry_metadata(entry: SuiteEntry) -> dict[str, Any]:
    """What scoring and the eq. 3 aggregate need of a manifest entry."""
    return {
        "task_id": entry.task_id,
        "source": entry.source,
        "condition": entry.condition,
        "object_id": entry.object_id,
        "category": entry.category,
        "n_parts": entry.n_parts,
        "weight": entry.weight,
        "variant": entry.variant,
    }


def suite_samples(suite_dir: Path, tasks: str | Sequence[str] | None = None) -> MemoryDataset:
    """The samples of ``suite_dir``'s tasks (or of the ``tasks`` subset), in suite order."""
    manifest = read_manifest(suite_dir)
    try:
        ids = manifest.select(task_filter(tasks))
    except ValueError as exc:
        raise ValueError(f"tasks={tasks}: {exc}") from None
    samples = []
    for tid in ids:
        task_dir, _ = suite_paths(suite_dir, tid)
        samples.append(Sample(id=tid, input=sample_input(task_dir), metadata=entry_metadata(manifest.entry(tid))))
    return MemoryDataset(samples, name=manifest.name, location=str(suite_dir))
