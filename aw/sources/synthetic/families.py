"""The refiners' benchmark families: blocks of broken objects beside the paper's four, built on
request (``aw-prepare synthetic --blocks breaks_planar,...``), never by default.

============== ============================================================== ======
family         what                                                           pieces
============== ============================================================== ======
breaks_planar  the five solids of :mod:`aw.sources.synthetic.breaks` cut by a      2
               plane; low-poly and dense meshes; a rod cut across (small cut
               faces), a lens split through its thickness (cut faces as large
               as the rest)
breaks_noisy   even objects: a planar cut, odd: a rough break of                  2
               :mod:`aw.sources.synthetic.fracture`; every surface with scan noise
breaks_eroded  the same kinds with chips taken out of the rims and the rims        2
               rounded
breaks_pieces  the five solids cut 2-4 times, rough and planar cuts alternating  3-5
============== ============================================================== ======

Object ``index`` of a family is drawn from ``default_rng([seed, family code, index, attempt])``
like the blocks' (:func:`aw.sources.synthetic.generate_object`).
"""

from __future__ import annotations

import numpy as np
import trimesh

from aw.sources.synthetic import breaks
from aw.sources.synthetic import fracture as _fracture
from aw.sources.synthetic.builder import Builder

__all__ = ["FAMILIES", "build_family", "family_plan"]

FAMILIES: dict[str, tuple[str, ...]] = {
    "breaks_planar": breaks.CUT_SHAPES,
    "breaks_noisy": breaks.CUT_SHAPES + _fracture.CATEGORIES,
    "breaks_eroded": breaks.CUT_SHAPES + _fracture.CATEGORIES,
    "breaks_pieces": breaks.CUT_SHAPES,
}
NAMES = tuple(f"fragment_{c}" for c in "abcdefgh")


def family_plan(family: str, index: int) -> tuple[str, int]:
    """(category, piece count) of object ``index`` of ``family``."""
    shapes, rough = breaks.CUT_SHAPES, _fracture.CATEGORIES
    if family == "breaks_planar":
        return shapes[index % len(shapes)], 2
    if family in ("breaks_noisy", "breaks_eroded"):
        kinds = shapes if index % 2 == 0 else rough
        return kinds[(index // 2) % len(kinds)], 2
    if family == "breaks_pieces":
        return shapes[index % len(shapes)], 3 + index % 3
    raise ValueError(f"unknown family {family!r}; choose from {', '.join(FAMILIES)}")


def _planar_cut(shape: str, rng: np.random.Generator, dense: bool, n: int = 2, rough=False) -> list[breaks.Piece]:
    whole = breaks.solid(shape, rng, dense)
    if shape == "rod":  # across the long axis, away from the middle: a small cut face
        return breaks.cut_pieces(whole, rng, n, rough, tilt_deg=30.0, axis=np.array([0.0, 0.0, 1.0]), offset=0.25)
    if shape == "lens":  # through the thickness: cut faces about as large as the rest
        return breaks.cut_pieces(whole, rng, n, rough, tilt_deg=12.0, axis=np.array([0.0, 0.0, 1.0]), offset=0.02)
    return breaks.cut_pieces(whole, rng, n, rough)


def _rough_break(category: str, rng: np.random.Generator) -> list[breaks.Piece]:
    b = Builder(category)
    _fracture.fracture(b, category, rng)
    return breaks.shared_faces([p.mesh for p in b.parts])


def build_family(b: Builder, family: str, index: int, rng: np.random.Generator) -> None:
    """Add object ``index`` of ``family`` to ``b`` (pieces ``fragment_a``, ``fragment_b``, ...)."""
    category, n = family_plan(family, index)
    dense = (index // 5) % 2 == 1
    if family == "breaks_pieces":
        meshes = [p.mesh for p in _planar_cut(category, rng, True, n, [(index + k) % 2 == 0 for k in range(n - 1)])]
    elif category in _fracture.CATEGORIES:
        pieces = _rough_break(category, rng)
    else:
        pieces = _planar_cut(category, rng, dense)
    if family == "breaks_planar":
        meshes = [p.mesh for p in pieces]
    elif family in ("breaks_noisy", "breaks_eroded"):
        size = float(np.ptp(np.vstack([p.mesh.vertices for p in pieces]), axis=0).max())
        if family == "breaks_noisy":
            meshes = [breaks.make_noisy(p, rng, size) for p in pieces]
        else:
            meshes = breaks.erode(pieces, rng, size)
    for name, mesh in zip(NAMES, meshes, strict=False):  # NAMES: more than enough
        b.add(name, trimesh.Trimesh(mesh.vertices, mesh.faces, process=False), step="fragments")
