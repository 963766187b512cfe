"""Procedural furniture: chairs, tables, storage, benches, desks and shelves (metres, Z up).

Generators build with the front of the furniture towards +Y; :func:`facing_camera` turns the
finished object so that its front faces the default camera (which looks from -Y). Every
generator takes the exact number of parts ``n`` it must produce and a seeded
``numpy.random.Generator``. Repeated members (legs, slats, shelves, doors, handles) are identical
copies recorded as equivalence groups; parts that are not meant to be identical get clearly
different proportions (checked again by :func:`aw.sources.synthetic.checks.accidental_twins`).
"""

from __future__ import annotations

import itertools

import numpy as np

from aw.pose import rotation_about_axis
from aw.sources.synthetic.builder import Builder
from aw.sources.synthetic.prims import box, cylinder, merge, placed, revolved

__all__ = ["PART_RANGES", "facing_camera", "chair", "table", "storage", "shelf", "bench", "desk"]

# Inclusive part-count range each generator can produce.
PART_RANGES = {
    "chair": (3, 20),
    "table": (2, 20),
    "storage": (5, 20),
    "shelf": (5, 16),
    "bench": (3, 16),
    "desk": (4, 20),
}


def facing_camera(b: Builder) -> None:
    """Turn every part 180 degrees about Z (fronts from +Y to -Y)."""
    b.transform_all(rotation_about_axis(2, np.pi))


def _pick_features(
    rng: np.random.Generator, features: dict[str, int], budget: int, fill_max: int, requires=None, conflicts=()
) -> list[str]:
    """A random subset of ``features`` (name -> part count) using at most ``budget`` parts and
    leaving at most ``fill_max`` parts for the caller's variable-count filler.

    ``requires``: feature -> features it needs; ``conflicts``: pairs that exclude each other.
    """
    requires = requires or {}
    names = list(features)
    options = []
    for r in range(len(names) + 1):
        for combo in itertools.combinations(names, r):
            if any(req not in combo for f in combo for req in requires.get(f, ())):
                continue
            if any(a in combo and b in combo for a, b in conflicts):
                continue
            used = sum(features[f] for f in combo)
            if used <= budget and budget - used <= fill_max:
                options.append(list(combo))
    if not options:
        raise ValueError(f"cannot reach the requested part count (budget {budget})")
    return options[int(rng.integers(len(options)))]


def _leg(rng: np.random.Generator, length: float, thick: float):
    """A leg about the origin along Z: square or round, or a tapered turned leg."""
    kind = int(rng.integers(3))
    if kind == 0:
        return box((thick, thick, length))
    if kind == 1:
        return cylinder(thick / 2, length, sections=20)
    r0, r1 = thick / 2, thick / 3
    return revolved(
        [[0, -length / 2], [r1, -length / 2], [r0, length * 0.3], [r0 * 0.8, length / 2], [0, length / 2]], sections=20
    )


def _handle(length: float, vertical: bool = False):
    """Bar handle about the origin, standing out along +Y: a grip bar on two posts."""
    stand = 0.03
    parts = [
        box((length, 0.012, 0.016), (0, stand, 0)),
        box((0.012, stand, 0.012), (-length / 2 + 0.012, stand / 2, 0)),
        box((0.012, stand, 0.012), (length / 2 - 0.012, stand / 2, 0)),
    ]
    m = merge(parts)
    return placed(m, (0, 0, 0), rotation_about_axis(1, np.pi / 2)) if vertical else m


def _spaced(count: int, span: float) -> np.ndarray:
    """``count`` centres evenly spread over ``[-span/2, span/2]``."""
    if count == 1:
        return np.zeros(1)
    return np.linspace(-span / 2, span / 2, count)


def chair(b: Builder, n: int, rng: np.random.Generator) -> None:
    h = rng.uniform(0.42, 0.48)  # seat top height
    sw, sd = rng.uniform(0.40, 0.52), rng.uniform(0.36, 0.46)
    st = rng.uniform(0.035, 0.055)
    bh = rng.uniform(0.34, 0.50)  # back height above the seat
    bt = rng.uniform(0.018, 0.028)
    seat_z = h - st / 2
    b.add("seat", box((sw, sd, st), (0, 0, seat_z)), step="seat")
    back_y = -sd / 2 + bt / 2
    if n <= 5:
        b.add("back", box((sw * 0.95, bt, bh), (0, back_y, h + bh / 2)), step="back")
        col_h = h - st - 0.06
        base_r = rng.uniform(0.24, 0.30)
        column = cylinder(0.025, col_h, (0, 0, 0.06 + col_h / 2))
        arms = [box((base_r, 0.05, 0.04), (base_r / 2, 0, 0.03))]
        base = merge([_rot_z(arms[0], 2 * np.pi * k / 5) for k in range(5)])
        if n == 3:
            b.add("pedestal", merge([column, base]), step="base")
        elif n == 4:
            b.add("column", column, step="base")
            b.add("star_base", base, step="base")
        else:  # sled chair: two identical side frames and a crossbar
            t = 0.025
            frame = merge(
                [
                    box((t, t, h - st), (0, sd / 2 - t, (h - st) / 2)),
                    box((t, t, h - st), (0, -sd / 2 + t, (h - st) / 2)),
                    box((t, sd + 0.06, t), (0, 0, t / 2)),
                ]
            )
            b.add_copies("side_frame", frame, [((-sw / 2 + t, 0, 0), None), ((sw / 2 - t, 0, 0), None)], step="base")
            b.add("crossbar", cylinder(0.012, sw - 2 * t, (0, -sd / 2 + t, 0.12), axis="x"), step="base")
        return

    lw = rng.uniform(0.03, 0.045)
    leg_len = h - st
    legs = [((sx * (sw / 2 - lw), sy * (sd / 2 - lw), leg_len / 2), None) for sx in (-1, 1) for sy in (-1, 1)]
    b.add_copies("leg", _leg(rng, leg_len, lw), legs, step="legs")

    r = n - 5
    feats = {"arms": 2, "arm_posts": 2, "rails_front_back": 2, "rails_side": 2}
    chosen = _pick_features(rng, feats, r - 1, fill_max=10, requires={"arm_posts": ("arms",)})
    back_count = r - sum(feats[f] for f in chosen)

    rail_z = rng.uniform(0.12, 0.2)
    if "rails_front_back" in chosen:
        rail = box((sw - 2 * lw, 0.018, 0.05))
        b.add_copies("rail_fb", rail, [((0, y, rail_z), None) for y in (sd / 2 - lw, -sd / 2 + lw)], step="rails")
    if "rails_side" in chosen:
        rail = cylinder(0.011, sd - 2 * lw, axis="y")
        b.add_copies(
            "rail_side", rail, [((x, 0, rail_z + 0.07), None) for x in (sw / 2 - lw, -sw / 2 + lw)], step="rails"
        )

    # back: panel, panel + crest, or two posts with a crest rail and vertical slats
    if back_count == 1:
        b.add("back", box((sw * 0.95, bt, bh), (0, back_y, h + bh / 2)), step="back")
    elif back_count == 2:
        b.add("back", box((sw * 0.9, bt, bh * 0.7), (0, back_y, h + bh * 0.35 + 0.02)), step="back")
        b.add("crest", box((sw, bt * 2.2, bh * 0.22), (0, back_y, h + bh * 0.89)), step="back")
    else:
        pw = rng.uniform(0.028, 0.04)
        post = box((pw, pw * 1.2, bh))
        xs = sw / 2 - pw / 2
        b.add_copies("back_post", post, [((x, back_y, h + bh / 2), None) for x in (-xs, xs)], step="back")
        crest_h = rng.uniform(0.06, 0.1)
        b.add("crest", box((sw - 2 * pw, bt * 1.6, crest_h), (0, back_y, h + bh - crest_h / 2)), step="back")
        slats = back_count - 3
        if slats:
            inner = sw - 2 * pw
            slat_w = min(0.06, inner / (2 * slats))
            slat_h = bh - crest_h - 0.03
            xs_slat = _spaced(slats, inner - slat_w - 0.04)
            slat = box((slat_w, bt * 0.7, slat_h))
            b.add_copies("back_slat", slat, [((x, back_y, h + 0.03 + slat_h / 2), None) for x in xs_slat], step="back")

    if "arms" in chosen:
        arm_z = h + rng.uniform(0.18, 0.24)
        arm = box((0.05, sd * 0.85, 0.025))
        ax = sw / 2 + 0.03
        b.add_copies("arm", arm, [((x, 0, arm_z), None) for x in (-ax, ax)], step="arms")
        if "arm_posts" in chosen:
            ph = arm_z - h
            post = cylinder(0.012, ph)
            b.add_copies("arm_post", post, [((x, sd * 0.3, h + ph / 2), None) for x in (-ax, ax)], step="arms")


def _rot_z(mesh, angle: float):
    return placed(mesh, (0, 0, 0), rotation_about_axis(2, angle))


def table(b: Builder, n: int, rng: np.random.Generator) -> None:
    h = rng.uniform(0.70, 0.76)
    tt = rng.uniform(0.025, 0.04)
    if n <= 4:
        radius = rng.uniform(0.35, 0.55)
        b.add("top", cylinder(radius, tt, (0, 0, h - tt / 2), sections=48), step="top")
        col_h = h - tt - 0.04
        column = cylinder(rng.uniform(0.03, 0.05), col_h, (0, 0, 0.04 + col_h / 2))
        foot = cylinder(radius * 0.55, 0.04, (0, 0, 0.02), sections=40)
        if n == 2:
            b.add("pedestal", merge([column, foot]), step="base")
        elif n == 3:
            b.add("column", column, step="base")
            b.add("foot", foot, step="base")
        else:
            lw = rng.uniform(0.03, 0.045)
            leg = _leg(rng, h - tt, lw)
            pos = [
                ((radius * 0.6 * np.cos(a), radius * 0.6 * np.sin(a), (h - tt) / 2), None)
                for a in 2 * np.pi * np.arange(3) / 3
            ]
            b.add_copies("leg", leg, pos, step="legs")
        return

    width = rng.uniform(0.6, 0.9)
    length = width * rng.uniform(1.3, 2.0)  # clearly oblong: long and short members differ
    lw = rng.uniform(0.04, 0.06)
    leg_len = h - tt
    inset = lw / 2 + 0.03
    lx, ly = length / 2 - inset, width / 2 - inset
    legs = [((sx * lx, sy * ly, leg_len / 2), None) for sx in (-1, 1) for sy in (-1, 1)]
    b.add_copies("leg", _leg(rng, leg_len, lw), legs, step="legs")

    r = n - 5
    feats = {"aprons_long": 2, "aprons_short": 2, "stretchers": 2, "center_stretcher": 1, "drawer": 2}
    chosen = _pick_features(
        rng,
        feats,
        r,
        fill_max=12,
        requires={"aprons_short": ("aprons_long",), "center_stretcher": ("stretchers",), "drawer": ("aprons_long",)},
    )
    fill = r - sum(feats[f] for f in chosen)
    planks = 1 + min(fill, int(rng.integers(0, 5)))  # the top may be made of identical planks
    shelf_slats = fill - (planks - 1)
    if shelf_slats > 8:
        planks += shelf_slats - 8
        shelf_slats = 8

    if planks == 1:
        b.add("top", box((length, width, tt), (0, 0, h - tt / 2)), step="top")
    else:
        pw = width / planks
        plank = box((length, pw - 0.004, tt))
        b.add_copies("top_plank", plank, [((0, y, h - tt / 2), None) for y in _spaced(planks, width - pw)], step="top")

    apron_h = rng.uniform(0.07, 0.11)
    az = h - tt - apron_h / 2
    if "aprons_long" in chosen:
        apron = box((2 * lx - lw, 0.02, apron_h))
        b.add_copies("apron_long", apron, [((0, y, az), None) for y in (-ly, ly)], step="aprons")
    if "aprons_short" in chosen:
        apron = box((0.02, 2 * ly - lw, apron_h * 0.8))
        b.add_copies("apron_short", apron, [((x, 0, az), None) for x in (-lx, lx)], step="aprons")
    sz = rng.uniform(0.12, 0.2)
    if "stretchers" in chosen:
        st = cylinder(0.014, 2 * ly - lw, axis="y")
        b.add_copies("stretcher", st, [((x, 0, sz), None) for x in (-lx, lx)], step="stretchers")
    if "center_stretcher" in chosen:
        b.add("center_stretcher", box((2 * lx - lw, 0.03, 0.045), (0, 0, sz)), step="stretchers")
    if "drawer" in chosen:
        dw = min(0.45, lx)
        b.add("drawer_front", box((dw, 0.022, apron_h * 0.85), (0, ly + 0.012, az)), step="drawer")
        b.add("drawer_pull", placed(_handle(rng.uniform(0.1, 0.16)), (0, ly + 0.023, az)), step="drawer")
    if shelf_slats:
        shelf_z = rng.uniform(0.08, 0.12) if "stretchers" not in chosen else sz + 0.04
        span_y = 2 * ly - lw
        if shelf_slats == 1:
            b.add("lower_shelf", box((2 * lx - lw, span_y, 0.015), (0, 0, shelf_z)), step="shelf")
        else:
            sw_ = span_y / shelf_slats
            slat = box((2 * lx - lw, sw_ * 0.8, 0.015))
            b.add_copies(
                "shelf_slat", slat, [((0, y, shelf_z), None) for y in _spaced(shelf_slats, span_y - sw_)], step="shelf"
            )


def _carcass(
    b: Builder, rng: np.random.Generator, width: float, depth: float, height: float, t: float, bottom_z: float
) -> None:
    """Two identical sides, identical top and bottom boards, and a thin back panel (5 parts)."""
    side = box((t, depth, height))
    b.add_copies(
        "side",
        side,
        [((x, 0, bottom_z + height / 2), None) for x in (-(width - t) / 2, (width - t) / 2)],
        step="carcass",
    )
    board = box((width - 2 * t, depth, t))
    b.add_copies(
        "board", board, [((0, 0, bottom_z + t / 2), None), ((0, 0, bottom_z + height - t / 2), None)], step="carcass"
    )
    b.add(
        "back_panel",
        box((width - 2 * t, 0.006, height - 2 * t), (0, -depth / 2 + 0.003, bottom_z + height / 2)),
        step="back",
    )


def storage(b: Builder, n: int, rng: np.random.Generator, doors: bool = True) -> None:
    width = rng.uniform(0.6, 1.0)
    depth = rng.uniform(0.3, 0.45)
    height = rng.uniform(0.7, 1.8)
    t = rng.uniform(0.016, 0.022)
    r = n - 5
    feats = {"feet": 4, "plinth": 1, "doors": 2, "handles": 2} if doors else {"feet": 4, "plinth": 1}
    chosen = _pick_features(rng, feats, r, fill_max=8, requires={"handles": ("doors",)}, conflicts=[("feet", "plinth")])
    shelves = r - sum(feats[f] for f in chosen)
    bottom_z = 0.0
    if "feet" in chosen:
        fh = rng.uniform(0.06, 0.12)
        foot = cylinder(0.02, fh, sections=16)
        fx, fy = width / 2 - 0.05, depth / 2 - 0.05
        b.add_copies(
            "foot", foot, [((sx * fx, sy * fy, fh / 2), None) for sx in (-1, 1) for sy in (-1, 1)], step="base"
        )
        bottom_z = fh
    elif "plinth" in chosen:
        ph = rng.uniform(0.05, 0.09)
        b.add("plinth", box((width - 0.04, depth - 0.04, ph), (0, 0, ph / 2)), step="base")
        bottom_z = ph
    _carcass(b, rng, width, depth, height, t, bottom_z)
    if shelves:
        inner_h = height - 2 * t
        shelf = box((width - 2 * t - 0.004, depth - 0.03, t * 0.8))
        zs = bottom_z + t + inner_h * (np.arange(1, shelves + 1) / (shelves + 1))
        b.add_copies("shelf", shelf, [((0, 0.012, z), None) for z in zs], step="shelves")
    if "doors" in chosen:
        dw = width / 2 - 0.003
        door = box((dw, 0.018, height - 0.01))
        b.add_copies(
            "door",
            door,
            [((x, depth / 2 + 0.009, bottom_z + height / 2), None) for x in (-width / 4, width / 4)],
            step="doors",
        )
        if "handles" in chosen:
            handle = _handle(min(0.3, height * rng.uniform(0.12, 0.25)), vertical=True)
            b.add_copies(
                "handle",
                handle,
                [((x, depth / 2 + 0.018, bottom_z + height * 0.55), None) for x in (-0.05, 0.05)],
                step="doors",
            )


def shelf(b: Builder, n: int, rng: np.random.Generator) -> None:
    """Open bookcase: a storage carcass without doors."""
    storage(b, n, rng, doors=False)


def bench(b: Builder, n: int, rng: np.random.Generator) -> None:
    length = rng.uniform(1.0, 1.6)
    depth = rng.uniform(0.32, 0.42)
    h = rng.uniform(0.42, 0.48)
    tt = rng.uniform(0.025, 0.035)
    frame_t = rng.uniform(0.04, 0.06)
    # two identical end frames (legs and a foot rail in one part)
    frame = merge(
        [
            box((frame_t, frame_t, h - tt), (0, depth / 2 - frame_t, (h - tt) / 2)),
            box((frame_t, frame_t, h - tt), (0, -depth / 2 + frame_t, (h - tt) / 2)),
            box((frame_t, depth, frame_t * 1.2), (0, 0, h - tt - frame_t * 0.6)),
        ]
    )
    fx = length / 2 - 0.08
    b.add_copies("end_frame", frame, [((x, 0, 0), None) for x in (-fx, fx)], step="frames")
    r = n - 2
    feats = {"stretcher": 1, "lower_rails": 2}
    chosen = _pick_features(rng, feats, r - 1, fill_max=10)
    planks = r - sum(feats[f] for f in chosen)
    if "stretcher" in chosen:
        b.add("stretcher", box((2 * fx - frame_t, 0.03, 0.06), (0, 0, 0.15)), step="frames")
    if "lower_rails" in chosen:
        rail = cylinder(0.012, 2 * fx - frame_t, axis="x")
        b.add_copies(
            "lower_rail",
            rail,
            [((0, y, 0.08), None) for y in (-depth / 2 + frame_t, depth / 2 - frame_t)],
            step="frames",
        )
    if planks == 1:
        b.add("seat", box((length, depth, tt), (0, 0, h - tt / 2)), step="seat")
    else:
        pw = depth / planks
        plank = box((length, pw - 0.006, tt))
        b.add_copies(
            "seat_plank", plank, [((0, y, h - tt / 2), None) for y in _spaced(planks, depth - pw)], step="seat"
        )


def desk(b: Builder, n: int, rng: np.random.Generator) -> None:
    width = rng.uniform(1.0, 1.5)
    depth = rng.uniform(0.55, 0.75)
    h = rng.uniform(0.72, 0.76)
    tt = rng.uniform(0.025, 0.035)
    pt = rng.uniform(0.018, 0.025)
    b.add("top", box((width, depth, tt), (0, 0, h - tt / 2)), step="top")
    side = box((pt, depth - 0.04, h - tt))
    b.add_copies(
        "side_panel", side, [((x, 0, (h - tt) / 2), None) for x in (-(width - pt) / 2, (width - pt) / 2)], step="sides"
    )
    b.add(
        "modesty_panel",
        box((width - 2 * pt, pt, (h - tt) * 0.45), (0, -depth / 2 + 0.05, h - tt - (h - tt) * 0.225)),
        step="sides",
    )
    r = n - 4
    # a drawer pedestal: drawers (front + pull each) inside a box under the top
    feats = {"pedestal_box": 1, "cable_tray": 1}
    chosen = _pick_features(rng, feats, r, fill_max=14)
    drawers_parts = r - sum(feats[f] for f in chosen)
    if drawers_parts % 2 == 1:  # a keyboard shelf takes the odd part
        b.add("keyboard_shelf", box((width * 0.5, depth * 0.5, 0.015), (0, 0.05, h - tt - 0.08)), step="shelf")
        drawers_parts -= 1
    drawers = drawers_parts // 2
    px = (width - pt) / 2 - 0.22
    if "pedestal_box" in chosen:
        b.add(
            "pedestal_box", box((0.4, depth - 0.08, (h - tt) * 0.7), (px, 0, (h - tt) * 0.35 + 0.02)), step="pedestal"
        )
    if "cable_tray" in chosen:
        b.add("cable_tray", box((width * 0.6, 0.12, 0.06), (-0.05, -depth / 2 + 0.12, h - tt - 0.05)), step="sides")
    if drawers:
        dh = min(0.16, (h - tt) * 0.65 / drawers)
        front = box((0.38, 0.02, dh - 0.008))
        zs = h - tt - 0.02 - dh / 2 - dh * np.arange(drawers)
        b.add_copies("drawer_front", front, [((px, depth / 2 - 0.05, z), None) for z in zs], step="drawers")
        pull = _handle(0.2)
        b.add_copies("drawer_pull", pull, [((px, depth / 2 - 0.04, z), None) for z in zs], step="drawers")
