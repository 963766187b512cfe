"""Benchmark composition (Section 3.3, Appendix A.1): which objects of each dataset become tasks.

Per source, objects are drawn at random with part-count stratification and category coverage:

* Bands ``2-5``, ``6-10``, ``11-20`` parts (objects outside 2..20 parts are not eligible). The
  ``n`` objects are split as evenly as possible over the bands that have candidates; a band with
  too few candidates gives its shortfall to the others (largest remaining pools first), and
  remainders go to the bands with the most candidates (ties: the smaller band first).
* Inside a band, categories take turns and each category's candidates are taken in a seeded
  random order. The turn order puts first the categories that earlier bands covered least
  (ties: sorted names rotated to a seeded random start), so every category gets an object
  before any gets a second one, across the whole source, as far as the quotas allow.
* Fantastic Breaks (two-part objects only) is sampled by category alone.

Everything is a pure function of the catalog and the seed (``numpy.random.default_rng`` seeded
with ``(seed, crc32(source))``), so composition is deterministic and independent of the order in
which the catalog was listed. Reference conditions per source follow Appendix A.1.
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = [
    "BANDS",
    "SOURCE_CONDITIONS",
    "CatalogEntry",
    "band_of",
    "allocate",
    "sample_source",
    "compose",
    "Composition",
]

BANDS: tuple[tuple[str, int, int], ...] = (("2-5", 2, 5), ("6-10", 6, 10), ("11-20", 11, 20))
"""Part-count bands ``(name, lo, hi)`` (inclusive)."""

SOURCE_CONDITIONS: dict[str, tuple[str, ...]] = {
    "partnet": ("none", "image"),
    "ikea_manual": ("manual",),
    "assemblybench": ("manual",),
    "fantastic_breaks": ("none",),
}
"""Reference conditions per benchmark source (Appendix A.1)."""

STRATIFY_PARTS: dict[str, bool] = {"fantastic_breaks": False}


@dataclass(frozen=True)
class CatalogEntry:
    """One candidate object: enough to sample it and to load it later in a worker process
    (``loader`` is ``"module:function"``, called as ``function(*args)``)."""

    source: str
    object_id: str
    category: str
    n_parts: int
    loader: str
    args: tuple = ()
    info: dict[str, Any] = field(default_factory=dict, compare=False, hash=False)

    @property
    def key(self) -> tuple[str, str]:
        return (self.category, self.object_id)


def band_of(n_parts: int) -> str | None:
    for name, lo, hi in BANDS:
        if lo <= n_parts <= hi:
            return name
    return None


def allocate(n: int, available: dict[str, int]) -> dict[str, int]:
    """Split ``n`` draws over strata with ``available[s]`` candidates each, as evenly as possible.

    Deterministic: remainders and shortfalls go to strata with more candidates left (ties to
    the earlier stratum in ``available``'s order). The total is ``min(n, sum(available))``.
    """
    names = [s for s, k in available.items() if k > 0]
    quota = {s: 0 for s in available}
    left = min(n, sum(available[s] for s in names))
    while left > 0:
        open_ = [s for s in names if quota[s] < available[s]]
        share, rem = divmod(left, len(open_))
        # the remainder goes to the strata with the most candidates left
        order = sorted(open_, key=lambda s: (-(available[s] - quota[s]), names.index(s)))
        for k, s in enumerate(order):
            want = share + (1 if k < rem else 0)
            take = min(want, available[s] - quota[s])
            quota[s] += take
            left -= take
    return quota


def _rng(seed: int, source: str) -> np.random.Generator:
    return np.random.default_rng([int(seed), zlib.crc32(source.encode())])


def _round_robin(
    pools: dict[str, list[CatalogEntry]], k: int, rng: np.random.Generator, counts: dict[str, int]
) -> list[CatalogEntry]:
    """``k`` entries taking categories in turn, each pool already shuffled. Categories that
    earlier strata covered less (``counts``, updated here) go first; ties from a seeded start."""
    cats = sorted(pools)
    if not cats or k <= 0:
        return []
    start = int(rng.integers(len(cats)))
    rotated = cats[start:] + cats[:start]
    cats = sorted(rotated, key=lambda c: (counts.get(c, 0), rotated.index(c)))
    taken: list[CatalogEntry] = []
    pos = {c: 0 for c in cats}
    while len(taken) < k:
        progressed = False
        for c in cats:
            if len(taken) == k:
                break
            if pos[c] < len(pools[c]):
                taken.append(pools[c][pos[c]])
                pos[c] += 1
                counts[c] = counts.get(c, 0) + 1
                progressed = True
        if not progressed:
            break
    return taken


def _shuffled_pools(entries: Sequence[CatalogEntry], rng: np.random.Generator) -> dict[str, list[CatalogEntry]]:
    pools: dict[str, list[CatalogEntry]] = {}
    for e in sorted(entries, key=lambda e: e.key):  # catalog order must not matter
        pools.setdefault(e.category, []).append(e)
    for cat in sorted(pools):
        order = rng.permutation(len(pools[cat]))
        pools[cat] = [pools[cat][i] for i in order]
    return pools


def sample_source(
    entries: Sequence[CatalogEntry], n: int, seed: int = 0, stratify_parts: bool | None = None
) -> list[CatalogEntry]:
    """``n`` objects of one source (fewer if the catalog is smaller), in a stable order
    (band, then category, then object id)."""
    if n < 0:
        raise ValueError("n must be >= 0")
    if not entries:
        return []
    sources = {e.source for e in entries}
    if len(sources) != 1:
        raise ValueError(f"sample_source takes one source at a time, got {sorted(sources)}")
    source = next(iter(sources))
    ids = [e.object_id for e in entries]
    dup = sorted({i for i in ids if ids.count(i) > 1})
    if dup:
        raise ValueError(f"{source}: duplicate object ids in the catalog {dup[:5]}")
    stratify = STRATIFY_PARTS.get(source, True) if stratify_parts is None else stratify_parts
    rng = _rng(seed, source)
    eligible = [e for e in entries if 2 <= e.n_parts <= 20]
    if stratify:
        strata = {name: [e for e in eligible if band_of(e.n_parts) == name] for name, _, _ in BANDS}
    else:
        strata = {"all": eligible}
    quota = allocate(n, {s: len(v) for s, v in strata.items()})
    chosen: list[CatalogEntry] = []
    counts: dict[str, int] = {}
    for s, members in strata.items():
        chosen.extend(_round_robin(_shuffled_pools(members, rng), quota[s], rng, counts))
    band_index = {name: k for k, (name, _, _) in enumerate(BANDS)}
    return sorted(chosen, key=lambda e: (band_index.get(band_of(e.n_parts) or "", 9), e.category, e.object_id))


@dataclass
class Composition:
    """Sampled objects per source, with the conditions each gets."""

    seed: int
    per_source: int
    selected: dict[str, list[CatalogEntry]]
    available: dict[str, int]

    def conditions(self, source: str) -> tuple[str, ...]:
        return SOURCE_CONDITIONS.get(source, ("none",))

    def summary(self) -> dict[str, Any]:
        """JSON-able record of the composition (written next to the suite)."""
        out: dict[str, Any] = {"seed": self.seed, "per_source": self.per_source, "sources": {}}
        for source, entries in self.selected.items():
            out["sources"][source] = {
                "candidates": self.available[source],
                "conditions": list(self.conditions(source)),
                "bands": {name: sum(band_of(e.n_parts) == name for e in entries) for name, _, _ in BANDS},
                "categories": {c: sum(e.category == c for e in entries) for c in sorted({e.category for e in entries})},
                "objects": [{"object_id": e.object_id, "category": e.category, "n_parts": e.n_parts} for e in entries],
            }
        return out


def compose(catalogs: dict[str, Sequence[CatalogEntry]], per_source: int = 20, seed: int = 0) -> Composition:
    """Sample ``per_source`` objects from each source's catalog."""
    selected = {src: sample_source(entries, per_source, seed) for src, entries in catalogs.items()}
    return Composition(seed, per_source, selected, {src: len(v) for src, v in catalogs.items()})


def specs_for(comp: Composition):
    """:class:`aw.prepare.ObjectSpec` per selected object (donor: the next object of the same
    source, for the distractor variant), and the source of each spec."""
    from aw.prepare import ObjectSpec

    specs, sources = [], []
    for source, entries in comp.selected.items():
        conds = comp.conditions(source)
        for i, e in enumerate(entries):
            donor = None
            if len(entries) > 1:
                d = entries[(i + 1) % len(entries)]
                donor = ObjectSpec(d.loader, tuple(d.args))
            specs.append(ObjectSpec(e.loader, tuple(e.args), conds, donor))
            sources.append(source)
    return specs, sources
