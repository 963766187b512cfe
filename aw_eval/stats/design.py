"""The benchmark design: which task belongs to which source, condition and object, and the
weights of eq. 3.

Overall (eq. 3) averages sources equally; inside a source its reference conditions are averaged
equally (PartNet: none and image), and inside a (source, condition) cell tasks are averaged with
their manifest weights (1 by default). For the paper's suite this is exactly
``1/4 [1/2 (PN_none + PN_image) + IKEA + AB + FB]``; custom sources are simply weighted equally.

Bootstrap and randomization tests resample or exchange *objects*: an object is a
``(source, object_id)`` pair, so the two PartNet conditions of one object move together.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["SOURCE_ORDER", "CONDITION_ORDER", "TaskMeta", "Design", "ordered_sources"]

SOURCE_ORDER = ("partnet", "ikea_manual", "assemblybench", "fantastic_breaks")
CONDITION_ORDER = ("none", "image", "manual")


def ordered_sources(names) -> list[str]:
    """The paper's four sources first (in Table 1's order), then custom sources sorted."""
    names = set(names)
    return [s for s in SOURCE_ORDER if s in names] + sorted(names - set(SOURCE_ORDER))


def _condition_key(c: str) -> tuple[int, str]:
    return (CONDITION_ORDER.index(c) if c in CONDITION_ORDER else len(CONDITION_ORDER), c)


@dataclass(frozen=True)
class TaskMeta:
    """What aggregation needs to know about one task (a manifest entry)."""

    task_id: str
    source: str
    condition: str
    object_id: str
    weight: float = 1.0
    category: str = ""
    n_parts: int = 0


@dataclass(frozen=True)
class Design:
    """Index arrays over ``T`` tasks, ``O`` objects, ``C`` cells and ``K`` sources.

    Attributes:
        tasks: the task metadata, in the order every ``(S, T)`` value matrix uses.
        sources: source names (paper order first), ``K`` of them.
        cells: ``(source, condition)`` pairs, grouped by source, ``C`` of them.
        objects: ``(source, object_id)`` pairs, grouped by source, ``O`` of them.
        task_cell: ``(T,)`` cell index of each task.
        task_object: ``(T,)`` object index of each task.
        cell_source: ``(C,)`` source index of each cell.
        object_source: ``(O,)`` source index of each object.
        task_weight: ``(T,)`` manifest weight of each task (within its cell).
        weights: ``(T,)`` weight of each task in Overall (eq. 3); sums to 1.
    """

    tasks: tuple[TaskMeta, ...]
    sources: tuple[str, ...]
    cells: tuple[tuple[str, str], ...]
    objects: tuple[tuple[str, str], ...]
    task_cell: np.ndarray
    task_object: np.ndarray
    cell_source: np.ndarray
    object_source: np.ndarray
    task_weight: np.ndarray
    weights: np.ndarray

    @classmethod
    def from_tasks(cls, tasks: Sequence[TaskMeta]) -> Design:
        tasks = tuple(tasks)
        if not tasks:
            raise ValueError("a design needs at least one task")
        ids = [t.task_id for t in tasks]
        if len(set(ids)) != len(ids):
            raise ValueError("duplicate task ids in the design")
        for t in tasks:
            if not (t.weight > 0 and np.isfinite(t.weight)):
                raise ValueError(f"task {t.task_id}: weight must be positive and finite, got {t.weight}")
        sources = tuple(ordered_sources(t.source for t in tasks))
        cells: list[tuple[str, str]] = []
        objects: list[tuple[str, str]] = []
        for s in sources:
            conds = sorted({t.condition for t in tasks if t.source == s}, key=_condition_key)
            cells += [(s, c) for c in conds]
            seen: dict[str, None] = {}
            for t in tasks:
                if t.source == s:
                    seen.setdefault(t.object_id, None)
            objects += [(s, o) for o in seen]
        cell_idx = {c: i for i, c in enumerate(cells)}
        obj_idx = {o: i for i, o in enumerate(objects)}
        src_idx = {s: i for i, s in enumerate(sources)}
        task_cell = np.array([cell_idx[(t.source, t.condition)] for t in tasks], dtype=np.int64)
        task_object = np.array([obj_idx[(t.source, t.object_id)] for t in tasks], dtype=np.int64)
        cell_source = np.array([src_idx[s] for s, _ in cells], dtype=np.int64)
        object_source = np.array([src_idx[s] for s, _ in objects], dtype=np.int64)
        task_weight = np.array([t.weight for t in tasks], dtype=np.float64)
        weights = overall_weights(task_cell, cell_source, task_weight)
        return cls(
            tasks,
            sources,
            tuple(cells),
            tuple(objects),
            task_cell,
            task_object,
            cell_source,
            object_source,
            task_weight,
            weights,
        )

    @property
    def n_tasks(self) -> int:
        return len(self.tasks)

    @property
    def task_ids(self) -> list[str]:
        return [t.task_id for t in self.tasks]

    def cell_weights(self) -> np.ndarray:
        """``(C, T)``: row ``c`` averages the tasks of cell ``c`` (manifest weights)."""
        m = np.zeros((len(self.cells), self.n_tasks))
        m[self.task_cell, np.arange(self.n_tasks)] = self.task_weight
        return m / m.sum(axis=1, keepdims=True)

    def source_weights(self) -> np.ndarray:
        """``(K, T)``: row ``k`` is source ``k``'s mean (its conditions averaged first)."""
        out = np.zeros((len(self.sources), self.n_tasks))
        cw = self.cell_weights()
        for k in range(len(self.sources)):
            cells = np.flatnonzero(self.cell_source == k)
            out[k] = cw[cells].mean(axis=0)
        return out

    def subset(self, mask: np.ndarray) -> Design:
        """The design of the tasks where ``mask: (T,)`` is true (weights recomputed)."""
        return Design.from_tasks([t for t, m in zip(self.tasks, mask, strict=True) if m])


def overall_weights(task_cell: np.ndarray, cell_source: np.ndarray, task_weight: np.ndarray) -> np.ndarray:
    """Eq. 3 weights ``(T,)``: sources equal, conditions within a source equal, tasks by weight."""
    n_sources = int(cell_source.max()) + 1
    cells_per_source = np.bincount(cell_source, minlength=n_sources)
    cell_total = np.bincount(task_cell, weights=task_weight, minlength=len(cell_source))
    per_cell = 1.0 / (n_sources * cells_per_source[cell_source])
    return per_cell[task_cell] * task_weight / cell_total[task_cell]
