"""Registering one fragment onto another: the global search over pairs of candidate regions, and
the score that ranks its answers.

For every pair of candidate regions (one of each fragment) of compatible areas and extents:

- two planar regions (planar cuts): normals opposed, centroids together, the in-plane turns whose
  outlines agree best (:func:`fit.inplane_turns`), each refined by the symmetric ICP of the two
  outlines (the compiled kernel of :mod:`aw.kernels.icp`); with three or more fragments, also
  laid on part of each other (a cut face split between two fragments) by a trimmed outline ICP;
- otherwise (rough breaks): the other region's mean normal against the anchor's at
  ``IN_PLANE_STEPS`` turns about it, each refined by ICP restricted to the two regions.

The best ``FINE_STARTS`` are refined again on denser samples. A fit's score is the area in
contact (the smaller of the two regions' areas in contact, over the smaller fragment's area),
scaled down by how far two planar outlines still miss each other and up by ``RUGGED_FACTOR``
when both regions are rough (two congruent flat faces, the end caps of a prism, meet as well as
a break does; a rough break seldom meets anything but its match), less twice the share of either
fragment sunk into the other.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from aw.refine.classical.contact import (
    IDENTITY,
    Tolerance,
    contact_share,
    coverage,
    inverse,
    objective,
    sunk_share,
    tolerance,
)
from aw.refine.classical.fit import (
    chamfer_rms,
    contact_icp,
    facing,
    inplane_turns,
    partial_placements,
    rotvec_matrix,
    symmetric_icp,
)
from aw.refine.classical.surface import Cloud, Fragment, Region

__all__ = ["Fit", "refine_pair", "register_pair", "score_fit"]

IN_PLANE_STEPS = 24
COARSE_ITERATIONS = 15
FINE_STARTS = 4
RUGGED_FACTOR = 1.25
AREA_RATIO = {True: 1.6, False: 2.5}  # the largest area ratio of two regions that may meet (planar, rough)
EXTENT_RATIO = 1.4  # the largest ratio of two rough regions' principal extents
ROUGH_PAIRS = 8  # rough pairs searched per pair of fragments, the most alike first
PARTIAL_ROUGH_PAIRS = 3  # the same with three or more fragments (each search is dearer)
SAME_DEG = 5.0
OUTLINE_SHARE = 0.2  # of eps: the outline misfit that halves a planar fit's score
PARTIAL_RATIO = 1.3  # two regions' area ratio above which one may meet only part of the other
PARTIAL_AREA_RATIO = 5.0  # the largest area ratio of two regions that may meet, with three or more fragments
PARTIAL_CENTRES = 2
POLISH = 0.3  # of eps: the pairing radius that local refinement ends with
PARTIAL_STEPS = 12  # turns tried at each of those centres
SAG_UNIT = 0.01  # of the size: sags failing to cancel by this much rank a pair as far down as areas e times apart


@dataclass
class Fit:
    """``other``'s frame -> ``anchor``'s: ``x_anchor = rot @ x_other + shift``; its score and the
    pair of regions it was found on (``None`` for a refined start)."""

    rot: np.ndarray
    shift: np.ndarray
    score: float
    regions: tuple[int, int] | None = None

    def inverse(self) -> Fit:
        regions = None if self.regions is None else (self.regions[1], self.regions[0])
        return Fit(self.rot.T, -self.rot.T @ self.shift, self.score, regions)


def score_fit(
    a: Fragment, b: Fragment, ra: Region, rb: Region, rot, shift, tol: Tolerance, fine: bool, partial: bool = False
) -> float:
    """The score of ``b`` placed by ``(rot, shift)`` against ``a`` on the regions ``ra``, ``rb``
    (``fine``: on the dense samples, else on the coarse ones; ``partial``: as in
    :func:`register_pair`)."""
    sa, sb = (ra.fine, rb.fine) if fine else (ra.coarse, rb.coarse)
    move = (rot, shift)
    back = inverse(move)
    touching = min(contact_share(sa, sb, tol, back) * ra.area, contact_share(sb, sa, tol, move) * rb.area)
    value = touching / min(a.mesh.area, b.mesh.area)
    if ra.planar and rb.planar:
        value *= _outline_fit(ra, rb, rot, shift, tol, partial)
    elif not ra.planar and not rb.planar:
        value *= RUGGED_FACTOR
    body_a, body_b = (a.body, b.body) if fine else (a.coarse_body, b.coarse_body)
    sunk = max(sunk_share(body_b, body_a, tol, move), sunk_share(body_a, body_b, tol, back))
    return value - 2.0 * sunk


def _outline_fit(ra: Region, rb: Region, rot: np.ndarray, shift: np.ndarray, tol: Tolerance, partial: bool) -> float:
    """How well two planar outlines meet, in [0, 1]: ``1 / (1 + (misfit / (OUTLINE_SHARE * eps))^2)``
    (the misfit: root mean square distance of the outlines) times the square of the mean
    agreement of the walls they meet (the cosine of the normals across each outline sample and
    its nearest in the other, at least 0): at a cut the walls run on from one fragment into the
    other; a half-turned face of the same outline leaves a crease. With ``partial`` (three or
    more fragments), a cut face may hold parts of two fragments' faces, so the outlines are also
    judged on the part of the smaller one that lies on the larger, the score scaled by that
    part's share, and the better of the two judgements counts."""
    moved, moved_walls = rb.outline @ rot.T + shift, rb.rim_normals @ rot.T
    j = cKDTree(moved).query(ra.outline)[1]
    whole = _seam(chamfer_rms(ra.outline, moved), np.einsum("ij,ij->i", ra.rim_normals, moved_walls[j]), tol)
    if not partial:
        return whole
    small, small_walls, big, big_walls = ra.outline, ra.rim_normals, moved, moved_walls
    if rb.area < ra.area:
        small, small_walls, big, big_walls = big, big_walls, small, small_walls
    dist, found = cKDTree(big).query(small)
    d, j = np.asarray(dist), np.asarray(found)
    on = d < OUTLINE_SHARE * tol.eps * 2
    if not on.any():
        return whole
    walls = np.einsum("ij,ij->i", small_walls[on], big_walls[j[on]])
    return max(whole, _seam(float(np.sqrt(np.mean(d[on] ** 2))), walls, tol, share=float(on.mean())))


def _seam(misfit: float, walls: np.ndarray, tol: Tolerance, share: float = 1.0) -> float:
    """``share`` times ``1 / (1 + (misfit / (OUTLINE_SHARE * eps))^2)`` times the square of the mean
    of ``walls (k,)`` (the cosines of the walls met across the outline samples), at least 0."""
    closeness = 1.0 / (1.0 + (misfit / (OUTLINE_SHARE * tol.eps)) ** 2)
    return share * closeness * max(0.0, float(np.mean(walls))) ** 2


def _meets_part(ra: Region, rb: Region, partial: bool) -> bool:
    """Whether, with ``partial`` (three or more fragments), one region may meet only part of the
    other: their areas differ by more than ``PARTIAL_RATIO``."""
    return partial and max(ra.area, rb.area) > PARTIAL_RATIO * min(ra.area, rb.area)


def _mismatch(ra: Region, rb: Region, size: float, partial: bool) -> float | None:
    """How unlike two regions are for meeting (0: alike), or ``None`` when they cannot meet: areas
    (and, for rough regions, principal extents) too different. Sags that fail to cancel (a
    break's bulge is its match's hollow) rank a pair lower but never rule it out: one region may
    hold more of the break than its match, and a wavy break's sag is poorly defined.
    ``partial``: with three or more fragments a break can meet part of another, so areas may
    differ more and extents are not compared."""
    planar = ra.planar and rb.planar
    area = np.log(max(ra.area, rb.area) / min(ra.area, rb.area))
    if area > np.log(PARTIAL_AREA_RATIO if partial else AREA_RATIO[planar]):
        return None
    if planar:
        return float(area) if len(ra.outline) and len(rb.outline) else None
    extents = np.log(
        np.maximum(ra.extents[:2], rb.extents[:2]) / np.maximum(np.minimum(ra.extents[:2], rb.extents[:2]), 1e-12)
    )
    if not partial and extents.max() > np.log(EXTENT_RATIO):
        return None
    sag = abs(ra.sag + rb.sag) / (SAG_UNIT * size)
    return float(area + (0.0 if partial else extents.sum()) + sag)


def register_pair(a: Fragment, b: Fragment, partial: bool = False) -> list[Fit]:
    """Fits of ``b`` onto ``a`` from the global search, best first. ``partial``: look for breaks
    that meet only part of each other too (objects of three or more fragments)."""
    tol = tolerance(a, b)
    size = max(a.size, b.size)
    found: list[tuple[float, int, int, int, np.ndarray, np.ndarray]] = []
    planar: list[tuple[float, int, int]] = []  # (mismatch, region of a, region of b)
    rough: list[tuple[float, int, int]] = []
    for ia, ra in enumerate(a.regions):
        for ib, rb in enumerate(b.regions):
            mismatch = _mismatch(ra, rb, size, partial)
            if mismatch is not None:
                (planar if ra.planar and rb.planar else rough).append((mismatch, ia, ib))
    # every planar pair (cheap), and the most alike rough pairs
    for _, ia, ib in planar + sorted(rough)[: PARTIAL_ROUGH_PAIRS if partial else ROUGH_PAIRS]:
        ra, rb = a.regions[ia], b.regions[ib]
        for rot, shift in _starts(ra, rb, tol, size, partial):
            score = score_fit(a, b, ra, rb, rot, shift, tol, fine=False, partial=partial)
            found.append((score, len(found), ia, ib, rot, shift))
    found.sort(key=lambda x: (-x[0], x[1]))
    chosen: list[tuple[int, int, np.ndarray, np.ndarray]] = []
    for _, _, ia, ib, rot, shift in found:  # distinct starts only: one basin refined once
        if not any(_same(rot, shift, r, t, tol.eps) for _, _, r, t in chosen):
            chosen.append((ia, ib, rot, shift))
        if len(chosen) == FINE_STARTS:
            break
    fits: list[Fit] = []
    refined = (_fine(a, b, ia, ib, rot, shift, tol, partial) for ia, ib, rot, shift in chosen)
    for fit in sorted(refined, key=lambda f: -f.score):
        if not any(_same(fit.rot, fit.shift, f.rot, f.shift, tol.eps) for f in fits):
            fits.append(fit)
    return fits


def _starts(ra: Region, rb: Region, tol: Tolerance, size: float, partial: bool) -> list[tuple[np.ndarray, np.ndarray]]:
    """Coarse placements of region ``rb`` against ``ra``: outlines laid on each other (two
    planar regions), else turns about the facing normals, each refined on the coarse samples.
    With ``partial``, a planar outline is also laid on part of the other (and only so when their
    areas differ), and, when the areas differ, a rough region's centre also goes to
    ``PARTIAL_CENTRES`` spread points of the larger."""
    meets_part = _meets_part(ra, rb, partial)
    if ra.planar and rb.planar:
        out = []
        if not meets_part:
            turns = inplane_turns(rb.outline, ra.outline, rb.centroid, ra.centroid, rb.normal, ra.normal)
            out += [symmetric_icp(rb.outline, ra.outline, rot, shift, size) for rot, shift in turns]
        if partial:  # two faces of like areas may still each hold a part the other lacks
            out += partial_placements(
                rb.outline, ra.outline, rb.centroid, ra.centroid, rb.normal, ra.normal, OUTLINE_SHARE * tol.eps
            )
        return out
    face = facing(rb.normal, ra.normal)
    centre_b = rb.coarse.points.mean(0)
    centres = [ra.coarse.points.mean(0)]
    if meets_part and ra.area > rb.area:
        centres += list(_spread(ra.coarse.points, PARTIAL_CENTRES))
    out = []
    for k, centre in enumerate(centres):
        steps = IN_PLANE_STEPS if k == 0 else PARTIAL_STEPS
        for angle in np.arange(steps) * 2 * np.pi / steps:
            rot = rotvec_matrix(angle * ra.normal) @ face
            shift = centre - rot @ centre_b
            out.append(contact_icp(rb.coarse, ra.coarse, rot, shift, 0.5 * size, tol.eps, COARSE_ITERATIONS))
    if meets_part and rb.area > ra.area:  # the smaller region is the anchor's: move the other's spread points onto it
        for centre in _spread(rb.coarse.points, PARTIAL_CENTRES):
            for angle in np.arange(PARTIAL_STEPS) * 2 * np.pi / PARTIAL_STEPS:
                rot = rotvec_matrix(angle * ra.normal) @ face
                shift = ra.coarse.points.mean(0) - rot @ centre
                out.append(contact_icp(rb.coarse, ra.coarse, rot, shift, 0.5 * size, tol.eps, COARSE_ITERATIONS))
    return out


def _spread(points: np.ndarray, count: int) -> np.ndarray:
    """``count`` points of ``points (n, 3)`` far apart (farthest-point sampling from the one
    farthest from the mean)."""
    chosen = [int(np.argmax(np.linalg.norm(points - points.mean(0), axis=1)))]
    dist = np.linalg.norm(points - points[chosen[0]], axis=1)
    for _ in range(count - 1):
        chosen.append(int(np.argmax(dist)))
        dist = np.minimum(dist, np.linalg.norm(points - points[chosen[-1]], axis=1))
    # halfway to the mean: a part of a break lies inside it, not on its rim
    return 0.5 * (points[chosen] + points.mean(0))


def _same(rot, shift, rot2, shift2, eps: float) -> bool:
    """Two placements within ``SAME_DEG`` and ``eps`` of each other."""
    cos = (np.trace(rot.T @ rot2) - 1) / 2
    return bool(cos > np.cos(np.radians(SAME_DEG)) and np.linalg.norm(shift - shift2) < eps)


def _fine(a: Fragment, b: Fragment, ia: int, ib: int, rot, shift, tol: Tolerance, partial: bool = False) -> Fit:
    """A fit refined on the regions' dense samples."""
    ra, rb = a.regions[ia], b.regions[ib]
    if ra.planar and rb.planar:
        whole = symmetric_icp(rb.outline, ra.outline, rot, shift, max(a.size, b.size))
        # with partial, the placement as it came may be better: a trimmed outline ICP is as fine as a part gets
        placements = [(rot, shift), whole] if partial else [whole]
    else:
        placements = [contact_icp(rb.fine, ra.fine, rot, shift, 4 * tol.eps, tol.eps)]
    fits = [Fit(r, t, score_fit(a, b, ra, rb, r, t, tol, fine=True, partial=partial), (ia, ib)) for r, t in placements]
    return max(fits, key=lambda f: f.score)


def _union(fragment: Fragment) -> Cloud:
    regions = fragment.regions
    return Cloud(np.vstack([r.fine.points for r in regions]), np.vstack([r.fine.normals for r in regions]))


def refine_pair(a: Fragment, b: Fragment, rot: np.ndarray, shift: np.ndarray, radius: float) -> Fit:
    """``b`` refined from a given placement: ICP on all candidate regions of both (within
    ``radius`` at first), then also on the pair of regions that meet best there; of the two, the
    one with the higher fracture objective (:func:`contact.objective`)."""
    if not a.regions or not b.regions:
        return Fit(rot, shift, -np.inf)
    tol = tolerance(a, b)
    union_a, union_b = _union(a), _union(b)
    rot, shift = contact_icp(union_b, union_a, rot, shift, radius, tol.eps)
    rot, shift = contact_icp(union_b, union_a, rot, shift, tol.eps, POLISH * tol.eps)  # only the closest pairs
    pairs = [(ia, ib) for ia in range(len(a.regions)) for ib in range(len(b.regions))]
    ia, ib = max(pairs, key=lambda p: coverage(a.regions[p[0]].fine, b.regions[p[1]].fine, tol, (rot, shift)))
    paired = _fine(a, b, ia, ib, rot, shift, tol)
    tols = {(0, 1): tol}
    whole = objective([a, b], [IDENTITY, (rot, shift)], tols)
    if objective([a, b], [IDENTITY, (paired.rot, paired.shift)], tols) > whole:
        return paired
    return Fit(rot, shift, whole, None)
