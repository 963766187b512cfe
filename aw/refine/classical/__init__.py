"""``classical``: fracture-surface registration without model weights, for two or more fragments.

1. Each fragment (:mod:`.surface`): its mesh's face normals filtered against noise, the mesh
   split into smooth regions at sharp rims, the large regions kept as candidate contacts (planar
   or rough), samples of its whole surface, its noise level.
2. Global search (no start state, or ``options["mode"] == "global"``; :mod:`.pairs`): every pair
   of fragments is registered by trying every pair of candidate regions of compatible areas:
   planar faces by laying their outlines on each other (symmetric ICP, the compiled kernel of
   :mod:`aw.kernels.icp`), rough ones by turning one against the other at 24 angles and ICP
   restricted to the two regions (point-to-plane, opposed normals only); every fit is scored by
   how much of both regions meet, less how far either fragment sinks into the other
   (:mod:`.contact`).
3. Assembly (:mod:`.assemble`): the anchor keeps its pose; the other fragments join one at a
   time, the best-scoring fit to a placed fragment first, charged for sinking into any placed
   fragment; with three or more, rounds of ICP of each against all the others follow.
4. Local refinement (a start state given, the default then): the same ICP from the start's
   relative poses. The result is kept only when the assembly's fracture objective (the area in
   contact less twice the area sunk, :func:`.contact.objective`) is higher than the start's;
   otherwise the start comes back unchanged, and the refiner's log (``refiner.log``) says so.

It stops being useful where fragments have no surface in common that is large enough to be a
region of its own (slivers, dust), and its time grows with the square of the number of
fragments (every pair is registered).
"""

from __future__ import annotations

import numpy as np

from aw.prepare.official_protocol import pose_of, rotation_of
from aw.refine.base import RefineRequest
from aw.refine.classical.assemble import Pose, assemble, assembly_objective, refine_jointly
from aw.refine.classical.pairs import refine_pair
from aw.refine.classical.surface import fragment

__all__ = ["refine"]

LOCAL_RADIUS = 0.15  # of the object's size: how far apart the local ICP pairs samples at first


def _log(message: str) -> None:
    print(message, flush=True)


def refine(request: RefineRequest) -> np.ndarray:
    """Poses ``(P, 7)``: the anchor keeps its initial pose, the other fragments are registered
    onto it (see the module docstring)."""
    n = len(request.part_ids)
    if n < 2:
        raise ValueError(f"the classical refiner needs at least two fragments, got {n}")
    mode = request.options.get("mode", "local" if request.given_initial_poses else "global")
    if mode not in ("local", "global"):
        raise ValueError(f"option mode must be local or global, got {mode!r}")
    rng = np.random.default_rng(request.seed)
    size = max(float(np.ptp(np.asarray(v), axis=0).max()) for v, _ in request.meshes)
    fragments = [
        fragment(np.asarray(v, dtype=np.float64), np.asarray(f), size, rng, keep_whole=n > 2) for v, f in request.meshes
    ]
    anchor = request.anchor
    init = np.asarray(request.initial_poses, dtype=np.float64)
    ra, ta = rotation_of(init[anchor, 3:]), init[anchor, :3]
    if mode == "global":
        poses = assemble(fragments, anchor, _log)
    else:
        # each fragment's mesh frame -> the anchor's mesh frame, as the start state has it
        start: list[Pose] = [(ra.T @ rotation_of(p[3:]), ra.T @ (p[:3] - ta)) for p in init]
        if n == 2:
            other = 1 - anchor
            fit = refine_pair(fragments[anchor], fragments[other], *start[other], LOCAL_RADIUS * size)
            poses = list(start)
            poses[other] = (fit.rot, fit.shift)
        else:
            poses = refine_jointly(fragments, anchor, start, rounds=3, radius=LOCAL_RADIUS * size)
        before, after = assembly_objective(fragments, start), assembly_objective(fragments, poses)
        if after <= before:
            _log(
                f"classical: kept the start state: its fracture objective {before:.4f} is not below the refined {after:.4f}"
            )
            return init.copy()
        _log(f"classical: fracture objective {before:.4f} at the start, {after:.4f} refined")
    out = np.array(init)
    for k, (rot, shift) in enumerate(poses):
        if k != anchor:
            out[k] = pose_of(ta + ra @ shift, ra @ rot)
    return out
