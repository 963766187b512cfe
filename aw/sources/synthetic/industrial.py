"""Procedural industrial assemblies: shafts, bearings, gears, plates, brackets and fasteners.

An assembly is a category-specific core (a few large parts) plus fastener sets (bolt, or bolt
and nut, or bolt, nut and washer) at the core's fastener sites, chosen so that the object has
exactly ``n`` parts. The fastener diameter is drawn log-uniformly between 3% and 20% of the
largest core part's size, so fasteners are small next to plates and housings: over the default
20 objects the largest-to-smallest part-size ratio has a median of about 5 (AssemblyBench: 4.39,
interquartile range 2.29-8.90), against about 2 for the furniture blocks.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from aw.sources.synthetic.builder import Builder
from aw.sources.synthetic.prims import (
    box,
    circle_profile,
    cylinder,
    gear_profile,
    merge,
    placed,
    polygon_profile,
    prism,
    revolved,
    ring_prism,
    tube,
)

__all__ = ["CATEGORIES", "PART_RANGE", "assembly"]

PART_RANGE = (3, 20)


@dataclass
class Site:
    """A fastener hole: head seat ``pos (3,)``, unit ``direction (3,)`` into the material, ``grip`` length."""

    pos: np.ndarray
    direction: np.ndarray
    grip: float


def _rot_from_neg_z(d: np.ndarray) -> np.ndarray:
    """Proper rotation taking -Z onto the unit vector ``d`` (Rodrigues)."""
    a = np.array([0.0, 0.0, -1.0])
    d = np.asarray(d, dtype=np.float64) / np.linalg.norm(d)
    v = np.cross(a, d)
    c = float(a @ d)
    if np.linalg.norm(v) < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1 + c)


def _hex_ring(across_flats: float, bore: float, height: float, k: int = 24):
    outer = polygon_profile(across_flats / np.sqrt(3), 6, k)
    return ring_prism(outer, circle_profile(bore / 2, k), height)


def _bolt(d: float, length: float):
    """Hex-head bolt about the origin: head on top of z = 0, shank down to -length."""
    head_h = 0.65 * d
    head = prism(polygon_profile(0.9 * d, 6), head_h, at=(0, 0, head_h / 2))
    shank = cylinder(d / 2, length, at=(0, 0, -length / 2), sections=16)
    return merge([head, shank])


def _plate_sites(w: float, dpt: float, top_z: float, thick: float, k: int, rng: np.random.Generator) -> list[Site]:
    """``k`` holes around the border of a ``w`` x ``dpt`` plate, seeded start, even spacing."""
    m = 0.1 * min(w, dpt)
    per = 2 * (w - 2 * m) + 2 * (dpt - 2 * m)
    start = rng.uniform(0, per)
    sites = []
    for i in range(k):
        s = (start + per * i / k) % per
        x0, y0, L1, L2 = -w / 2 + m, -dpt / 2 + m, w - 2 * m, dpt - 2 * m
        if s < L1:
            x, y = x0 + s, y0
        elif s < L1 + L2:
            x, y = x0 + L1, y0 + (s - L1)
        elif s < 2 * L1 + L2:
            x, y = x0 + L1 - (s - L1 - L2), y0 + L2
        else:
            x, y = x0, y0 + L2 - (s - 2 * L1 - L2)
        sites.append(Site(np.array([x, y, top_z]), np.array([0.0, 0.0, -1.0]), thick))
    return sites


def _core_flange_coupling(b: Builder, rng: np.random.Generator, core: int) -> Callable[[int], list[Site]]:
    """Two identical flanges joining two shafts along X (core 3: one shaft through both)."""
    r_sh = rng.uniform(0.012, 0.02)
    r_fl = r_sh * rng.uniform(3.2, 4.2)
    t_fl = rng.uniform(0.012, 0.018)
    hub_r, hub_l = r_sh * 1.8, t_fl * 1.2
    flange = revolved(
        [[0, 0], [r_fl, 0], [r_fl, t_fl], [hub_r, t_fl], [hub_r, t_fl + hub_l], [0, t_fl + hub_l]], sections=40
    )
    rot_px = np.array([[0, 0, 1.0], [0, 1, 0], [-1, 0, 0]])  # +Z -> +X
    rot_nx = np.array([[0, 0, -1.0], [0, 1, 0], [1, 0, 0]])  # +Z -> -X
    b.add_copies("flange", flange, [((0.0005, 0, 0), rot_px), ((-0.0005, 0, 0), rot_nx)], step="flanges")
    l1 = rng.uniform(0.12, 0.2)
    if core == 3:
        b.add("shaft", cylinder(r_sh, 2 * l1, axis="x", sections=28), step="shafts")
    else:
        l2 = l1 * rng.uniform(1.3, 1.8)
        b.add("shaft_a", cylinder(r_sh, l1, at=(l1 / 2 - 0.01, 0, 0), axis="x", sections=28), step="shafts")
        b.add(
            "shaft_b",
            revolved(
                [[0, 0], [r_sh, 0], [r_sh, l2 * 0.6], [r_sh * 0.8, l2 * 0.6], [r_sh * 0.8, l2], [0, l2]],
                at=(-l2 + 0.01, 0, 0),
                axis="x",
                sections=28,
            ),
            step="shafts",
        )

    def sites(k: int) -> list[Site]:
        out = []
        rb = 0.5 * (hub_r + r_fl)
        for i in range(k):
            a = 2 * np.pi * i / k
            out.append(
                Site(
                    np.array([-t_fl - 0.0005, rb * np.cos(a), rb * np.sin(a)]), np.array([1.0, 0, 0]), 2 * t_fl + 0.001
                )
            )
        return out

    return sites


def _core_pillow_block(b: Builder, rng: np.random.Generator, core: int) -> Callable[[int], list[Site]]:
    """Base plate, shaft along X, bearing housings (core 3: one; 4: two), bearings (6), pulley (7)."""
    w, dpt, t = rng.uniform(0.25, 0.4), rng.uniform(0.1, 0.16), rng.uniform(0.008, 0.014)
    b.add("base_plate", box((w, dpt, t), (0, 0, t / 2)), step="base")
    r_sh = rng.uniform(0.01, 0.016)
    r_b = r_sh * 2.2
    axis_z = t + r_b * 1.8
    hw = r_b * 1.6
    housing = merge(
        [
            box((hw, dpt * 0.8, axis_z - t), (0, 0, (axis_z - t) / 2)),
            tube(r_b, r_b * 1.5, hw, at=(0, 0, axis_z - t), axis="x"),
        ]
    )
    xs = [0.0] if core == 3 else [-w * 0.3, w * 0.3]
    b.add_copies("housing", housing, [((x, 0, t), None) for x in xs], step="housings")
    shaft_len = w * rng.uniform(1.05, 1.3)
    b.add(
        "shaft",
        revolved(
            [[0, 0], [r_sh * 0.8, 0], [r_sh * 0.8, 0.03], [r_sh, 0.03], [r_sh, shaft_len], [0, shaft_len]],
            at=(-shaft_len / 2, 0, axis_z),
            axis="x",
            sections=24,
        ),
        step="shaft",
    )
    if core >= 6:
        bearing = tube(r_sh, r_b, hw * 0.8, axis="x", sections=28)
        b.add_copies("bearing", bearing, [((x, 0, axis_z), None) for x in xs], step="bearings")
    if core >= 7:
        pulley = revolved(
            [[0, 0], [r_b * 2.4, 0], [r_b * 2.0, 0.012], [r_b * 2.4, 0.024], [0, 0.024]],
            at=(w * 0.5, 0, axis_z),
            axis="x",
            sections=40,
        )
        b.add("pulley", pulley, step="pulley")

    def sites(k: int) -> list[Site]:
        return _plate_sites(w, dpt, t, t, k, rng)

    return sites


def _core_gear_train(b: Builder, rng: np.random.Generator, core: int) -> Callable[[int], list[Site]]:
    """Plate with vertical shafts carrying meshing gears (core 3: one shaft; 5: two), bearings (7), cover (8)."""
    n_shafts = 1 if core == 3 else 2
    t = rng.uniform(0.008, 0.012)
    r_sh = rng.uniform(0.006, 0.01)
    module = rng.uniform(0.004, 0.006)
    teeth = [int(rng.integers(12, 20)), int(rng.integers(26, 40))][:n_shafts]
    radii = [module * z / 2 for z in teeth]
    centres = [0.0] if n_shafts == 1 else [-radii[1] * 0.55, radii[0] + radii[1] * 0.45]
    w = max(0.12, sum(2 * r for r in radii) + 0.06)
    dpt = max(0.1, 2 * max(radii) + 0.05)
    b.add("plate", box((w, dpt, t), (0, 0, t / 2)), step="plate")
    gear_t = rng.uniform(0.01, 0.016)
    for i, (x, z, r) in enumerate(zip(centres, teeth, radii, strict=True)):
        shaft_len = rng.uniform(0.06, 0.09) + 0.02 * i
        b.add(
            f"shaft_{'ab'[i]}",
            cylinder(r_sh, shaft_len, at=(x, 0, t + shaft_len / 2 - 0.004), sections=20),
            step="shafts",
        )
        outline = gear_profile(r - 1.1 * module, r + module, z, per_tooth=8)
        gear = ring_prism(outline, circle_profile(r_sh, z * 8), gear_t, at=(x, 0, t + 0.02 + gear_t / 2))
        b.add(f"gear_{z}t", gear, step="gears")
    if core >= 7:
        bearing = tube(r_sh, r_sh * 2.1, 0.008, sections=24)
        b.add_copies("bearing", bearing, [((x, 0, t + 0.004), None) for x in centres], step="bearings")
    if core >= 8:
        b.add("cover", box((w * 0.8, dpt * 0.9, 0.004), (0, 0, t + 0.07)), step="cover")

    def sites(k: int) -> list[Site]:
        return _plate_sites(w, dpt, t, t, k, rng)

    return sites


def _core_motor_mount(b: Builder, rng: np.random.Generator, core: int) -> Callable[[int], list[Site]]:
    """L bracket on a base plate holding a motor body with a shaft pulley (core 3..5)."""
    w, dpt, t = rng.uniform(0.14, 0.22), rng.uniform(0.12, 0.18), rng.uniform(0.006, 0.01)
    bh = rng.uniform(0.08, 0.12)
    bt = t * 1.2
    # L profile in the YZ plane, extruded along X (kernel point at the inner corner)
    lprof = np.array([[0, 0], [dpt * 0.6, 0], [dpt * 0.6, bt], [bt, bt], [bt, bh], [0, bh]])
    bracket = prism(lprof, w * 0.6, axis="z", centre=(bt / 2, bt / 2))
    # prism builds the profile in XY and extrudes along Z; map (x, y, z) -> (z, x - dpt/2, y)
    bracket = placed(bracket, (0, -dpt * 0.3, 0), np.array([[0, 0, 1.0], [1, 0, 0], [0, 1, 0]]))
    r_m = rng.uniform(0.03, 0.045)
    motor_len = rng.uniform(0.07, 0.12)
    cz = t + bt + r_m + 0.004
    y_face = -dpt * 0.3 + bt
    if core >= 4:
        b.add("base_plate", box((w, dpt, t), (0, 0, t / 2)), step="base")
        z0 = t
    else:
        z0 = 0.0
        cz -= t
    b.add("bracket", placed(bracket, (0, 0, z0)), step="bracket")
    body = revolved(
        [
            [0, 0],
            [r_m, 0],
            [r_m, motor_len],
            [r_m * 0.4, motor_len],
            [r_m * 0.4, motor_len + 0.006],
            [0, motor_len + 0.006],
        ],
        sections=36,
    )
    rot_py = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])  # +Z -> +Y
    b.add("motor", placed(body, (0, y_face, cz), rot_py), step="motor")
    shaft_l = rng.uniform(0.03, 0.05)
    if core >= 5:
        pulley = revolved([[0, 0], [r_m * 0.7, 0], [r_m * 0.55, 0.008], [r_m * 0.7, 0.016], [0, 0.016]], sections=36)
        b.add(
            "pulley",
            placed(pulley, (0, y_face - shaft_l * 0.6, cz), np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])),
            step="pulley",
        )
    b.add(
        "motor_shaft",
        cylinder(0.004, shaft_l, at=(0, y_face - shaft_l / 2 + 0.004, cz), axis="y", sections=14),
        step="motor",
    )

    def sites(k: int) -> list[Site]:
        if core >= 4:
            return _plate_sites(w, dpt, t, t, k, rng)
        xs = np.linspace(-w * 0.25, w * 0.25, k) if k > 1 else np.zeros(1)
        return [Site(np.array([x, -dpt * 0.05, z0 + bt]), np.array([0, 0, -1.0]), bt) for x in xs]

    return sites


CATEGORIES: dict[str, Callable] = {
    "flange_coupling": _core_flange_coupling,
    "pillow_block": _core_pillow_block,
    "gear_train": _core_gear_train,
    "motor_mount": _core_motor_mount,
}
_CORE_SIZES = {
    "flange_coupling": (3, 4),
    "pillow_block": (3, 4, 6, 7),
    "gear_train": (3, 5, 7, 8),
    "motor_mount": (3, 4, 5),
}


def _plan(n: int, rng: np.random.Generator, cores: tuple[int, ...]) -> tuple[int, int, int]:
    """(core size, parts per fastener set, number of sets) with ``core + per_set * sets == n``."""
    options = [(c, m, k) for c in cores for m in (1, 2, 3) for k in range(0, 13) if c + m * k == n and (k or m == 1)]
    if not options:
        raise ValueError(f"no industrial plan with {n} parts")
    return options[int(rng.integers(len(options)))]


def assembly(b: Builder, category: str, n: int, rng: np.random.Generator) -> None:
    """Build an industrial assembly of ``category`` with exactly ``n`` parts."""
    core, m, k = _plan(n, rng, _CORE_SIZES[category])
    sites_for = CATEGORIES[category](b, rng, core)
    if not k:
        return
    sites = sites_for(k)
    # fastener diameter relative to the largest core part: this sets the part-size ratio
    core_size = max(float(np.linalg.norm(np.ptp(np.asarray(p.mesh.vertices), axis=0))) for p in b.parts)
    d = core_size * float(np.exp(rng.uniform(np.log(0.03), np.log(0.2))))
    if len(sites) > 1:  # neighbouring heads (1.8 d across corners) must not overlap
        pos = np.array([s.pos for s in sites])
        spacing = min(float(np.linalg.norm(a - b)) for i, a in enumerate(pos) for b in pos[i + 1 :])
        d = min(d, spacing / 2.0)
    grip = max(s.grip for s in sites)
    nut_h = 0.8 * d
    bolt = _bolt(d, grip + (nut_h + 0.6 * d if m >= 2 else 0.5 * d) + (0.2 * d if m == 3 else 0))
    washer = tube(0.55 * d, 1.05 * d, 0.2 * d, sections=24)
    nut = _hex_ring(1.6 * d, d, nut_h)
    head_off = 0.2 * d if m == 3 else 0.0
    bolts, nuts, washers = [], [], []
    for s in sites:
        rot = _rot_from_neg_z(s.direction)
        bolts.append((s.pos - s.direction * head_off, rot))
        nuts.append((s.pos + s.direction * (s.grip + nut_h / 2), rot))
        washers.append((s.pos - s.direction * (0.1 * d), rot))
    if m == 3:
        b.add_copies("washer", washer, washers, step="washers")
    b.add_copies("bolt", bolt, bolts, step="bolts")
    if m >= 2:
        b.add_copies("nut", nut, nuts, step="nuts")
