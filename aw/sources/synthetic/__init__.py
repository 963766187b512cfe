"""The embedded procedural benchmark: deterministic-by-seed objects for the paper's four blocks.

=================  =====================================  ==========  =====================
block              what                                   parts       conditions
=================  =====================================  ==========  =====================
partnet            chairs, tables, storage                2-20        none and image
ikea_manual        chairs, tables, benches, desks, shelf  2-20        manual (step pages)
assemblybench      flange couplings, pillow blocks, gear  3-20        manual (one per step)
                   trains, motor mounts with fasteners
fantastic_breaks   solids broken along a rough surface    2           none
=================  =====================================  ==========  =====================

Beside them, built only when named, the refiners' benchmark families
(:mod:`aw.sources.synthetic.families`: planar cuts, noisy and eroded breaks, 3-5 pieces).

Object ``index`` of a block takes the part-count band ``index % 3`` (2-5, 6-10, 11-20; clipped
to what the category can build) and a category that cycles so that every category meets every
band. Everything is drawn from ``numpy.random.default_rng([seed, block number, index])``; a
draw that makes two unrelated parts near-identical is redrawn (``attempt`` appended to the
seed), so the same ``(block, index, seed)`` always gives the same object.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from aw.assembly import AssembledObject
from aw.sources.synthetic import families as _families
from aw.sources.synthetic import fracture as _fracture
from aw.sources.synthetic import furniture as _furniture
from aw.sources.synthetic import industrial as _industrial
from aw.sources.synthetic.builder import Builder
from aw.sources.synthetic.checks import accidental_twins

__all__ = ["BLOCKS", "BANDS", "FAMILIES", "Block", "generate_object", "generate_block", "iter_suite_objects"]

BANDS: tuple[tuple[int, int], ...] = ((2, 5), (6, 10), (11, 20))
_MAX_ATTEMPTS = 20


@dataclass(frozen=True)
class Block:
    name: str
    categories: tuple[str, ...]
    conditions: tuple[str, ...]


BLOCKS: dict[str, Block] = {
    "partnet": Block("partnet", ("chair", "table", "storage"), ("none", "image")),
    "ikea_manual": Block("ikea_manual", ("chair", "table", "bench", "desk", "shelf"), ("manual",)),
    "assemblybench": Block("assemblybench", tuple(_industrial.CATEGORIES), ("manual",)),
    "fantastic_breaks": Block("fantastic_breaks", _fracture.CATEGORIES, ("none",)),
}
# the refiners' benchmark families: built when named, never by default
FAMILIES: dict[str, Block] = {name: Block(name, cats, ("none",)) for name, cats in _families.FAMILIES.items()}


def _code(block: str) -> int:
    """The block's number in the random streams (families after the blocks, from 10)."""
    return list(BLOCKS).index(block) if block in BLOCKS else 10 + list(FAMILIES).index(block)


def _part_range(block: str, category: str) -> tuple[int, int]:
    if block == "fantastic_breaks":
        return (2, 2)
    if block == "assemblybench":
        return _industrial.PART_RANGE
    return _furniture.PART_RANGES[category]


def plan(block: str, index: int, seed: int = 0) -> tuple[str, int]:
    """(category, part count) of object ``index`` of ``block`` (one of the blocks or families)."""
    if block not in BLOCKS and block not in FAMILIES:
        raise ValueError(f"unknown block {block!r}; choose from {sorted(BLOCKS) + sorted(FAMILIES)}")
    if index < 0:
        raise ValueError("index must be >= 0")
    if block in FAMILIES:
        return _families.family_plan(block, index)
    cats = BLOCKS[block].categories
    category = cats[(index % 3 + index // 3) % len(cats)]
    lo_c, hi_c = _part_range(block, category)
    lo_b, hi_b = BANDS[index % 3]
    lo, hi = max(lo_b, lo_c), min(hi_b, hi_c)
    if lo > hi:  # the category cannot reach this band: nearest count it can build
        lo = hi = lo_c if hi_b < lo_c else hi_c
    rng = np.random.default_rng([seed, list(BLOCKS).index(block), index, 0xC0])
    return category, int(rng.integers(lo, hi + 1))


def _build(block: str, index: int, category: str, n: int, rng: np.random.Generator) -> Builder:
    b = Builder(category)
    if block in FAMILIES:
        _families.build_family(b, block, index, rng)
    elif block == "fantastic_breaks":
        _fracture.fracture(b, category, rng)
    elif block == "assemblybench":
        _industrial.assembly(b, category, n, rng)
    else:
        getattr(_furniture, category)(b, n, rng)
        _furniture.facing_camera(b)
    return b


def generate_object(block: str, index: int, seed: int = 0) -> AssembledObject:
    """Object ``index`` of ``block`` for ``seed`` (same arguments, same object)."""
    category, n = plan(block, index, seed)
    code = _code(block)
    for attempt in range(_MAX_ATTEMPTS):
        rng = np.random.default_rng([seed, code, index, attempt])
        b = _build(block, index, category, n, rng)
        if b.n_parts != n:
            raise RuntimeError(f"generator {block}/{category} made {b.n_parts} parts instead of {n}")
        obj = b.build(
            object_id=f"{category}_{index:03d}",
            source=block,
            meta={"generator": "aw.sources.synthetic", "seed": seed, "index": index, "attempt": attempt},
        )
        if not accidental_twins(obj):
            return obj
    raise RuntimeError(f"{block}/{category} #{index}: every draw had near-identical unrelated parts")


def generate_block(block: str, count: int, seed: int = 0) -> list[AssembledObject]:
    """Objects ``0 .. count - 1`` of ``block``."""
    return [generate_object(block, i, seed) for i in range(count)]


def iter_suite_objects(per_source: int, seed: int = 0) -> Iterator[tuple[AssembledObject, tuple[str, ...]]]:
    """Every block's objects with the conditions to build for them (PartNet: none and image)."""
    for name, block in BLOCKS.items():
        for i in range(per_source):
            yield generate_object(name, i, seed), block.conditions
