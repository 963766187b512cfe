"""The up axis of imported objects: Y-up furniture (FurnitureBench's stool and square table:
extents x 0.163 / y 0.094 / z 0.163) is stood upright, Z-up objects are left as they are,
``meta.json`` and ``--up-axis`` override the geometry, and the choice is said per object."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from aw.cli.prepare import main
from aw.formats import read_manifest, read_targets, read_task
from aw.formats.suite import suite_paths
from aw.meshes import load_task_meshes
from aw.pose import apply_pose
from aw.sources.folder import load_object
from aw.sources.up_axis import guess_up_axis, stable_on_base, standing_counts

W, H = 0.163, 0.094  # FurnitureBench stool / square table: 0.163 wide and deep, 0.094 tall (Y up)


def _box(extents, centre) -> trimesh.Trimesh:
    return trimesh.creation.box(extents=extents).apply_translation(centre)


def y_up_stool() -> dict[str, trimesh.Trimesh]:
    """A round seat on three legs, Y up: extents x 0.163, y 0.094, z 0.163."""
    seat = trimesh.creation.cylinder(radius=W / 2, height=0.012, sections=32)
    seat.apply_transform(trimesh.transformations.rotation_matrix(-np.pi / 2, [1, 0, 0]))  # axis Z -> Y
    seat.apply_translation([0, H - 0.006, 0])
    parts = {"seat": seat}
    for k, a in enumerate(2 * np.pi * np.arange(3) / 3):
        parts[f"leg{k + 1}"] = _box((0.012, H - 0.012, 0.012), (0.06 * np.cos(a), (H - 0.012) / 2, 0.06 * np.sin(a)))
    return parts


def y_up_square_table() -> dict[str, trimesh.Trimesh]:
    """A square top on four legs, Y up: extents x 0.163, y 0.094, z 0.163."""
    parts = {"top": _box((W, 0.012, W), (0, H - 0.006, 0))}
    for k, (x, z) in enumerate([(-1, -1), (-1, 1), (1, -1), (1, 1)]):
        parts[f"leg{k + 1}"] = _box((0.012, H - 0.012, 0.012), (x * 0.07, (H - 0.012) / 2, z * 0.07))
    return parts


def z_up(parts: dict[str, trimesh.Trimesh]) -> dict[str, trimesh.Trimesh]:
    """The same object stored Z-up: (x, y, z) -> (x, -z, y)."""
    out = {}
    for name, m in parts.items():
        v = np.asarray(m.vertices)
        out[name] = trimesh.Trimesh(np.stack([v[:, 0], -v[:, 2], v[:, 1]], axis=1), m.faces, process=False)
    return out


def write_object(root, name, parts, meta=None):
    d = root / name
    d.mkdir(parents=True)
    for part, mesh in parts.items():
        mesh.export(d / f"{part}.obj")
    if meta is not None:
        (d / "meta.json").write_text(json.dumps(meta))
    return d


@pytest.mark.parametrize("make", [y_up_stool, y_up_square_table])
def test_y_up_furniture_is_detected_and_z_up_furniture_kept(make):
    parts = list(make().values())
    ext = np.ptp(np.concatenate([m.vertices for m in parts]), axis=0)
    np.testing.assert_allclose(ext, [W, H, W], atol=2e-3)
    assert standing_counts(parts)["y"] == len(parts) - 1  # the legs; the top is not elongated
    got = guess_up_axis(parts)
    assert got.axis == "y" and "stand along Y" in got.reason and "rests stably" in got.reason
    assert guess_up_axis(list(z_up(make()).values())).axis == "z"


def test_objects_without_upright_members_or_that_would_fall_keep_z():
    boxes = [_box((0.3, 0.2, 0.1), (0, 0, 0.05)), _box((0.5, 0.2, 0.15), (0, 0, 0.2))]
    assert guess_up_axis(boxes).axis == "z" and "0 parts stand along Y" in guess_up_axis(boxes).reason
    # two rods along Y on a single rod: upright along Y it would stand on one thin leg at the edge
    rods = [_box((0.02, 0.4, 0.02), (x, 0.2, 0.0)) for x in (-0.3, 0.3)] + [_box((0.6, 0.02, 0.02), (0, 0.41, 0))]
    rods.append(_box((0.02, 0.2, 0.02), (0.3, -0.1, 0)))  # the lowest part: the only base
    assert not stable_on_base(rods, "y")
    assert guess_up_axis(rods).reason.endswith("would not rest stably with Y up; kept Z")


def test_a_bar_broken_in_two_lying_along_y_keeps_z():
    halves = [_box((0.04, 0.3, 0.04), (0, -0.15, 0.02)), _box((0.04, 0.3, 0.04), (0, 0.15, 0.02))]
    got = guess_up_axis(halves)
    assert (
        got.axis == "z" and got.reason == "2 parts stand along Y, 0 along Z, but end to end, not side by side; kept Z"
    )


def test_the_synthetic_benchmark_objects_all_keep_z():
    from aw.sources.synthetic import BLOCKS, generate_object

    for block in BLOCKS:
        for i in range(5):
            obj = generate_object(block, i, 0)
            assert guess_up_axis([p.mesh for p in obj.parts]).axis == "z", (block, i, obj.category)


def test_load_object_turns_y_up_upright_and_respects_overrides(tmp_path):
    d = write_object(tmp_path, "stool", y_up_stool())
    obj = load_object(d)
    assert obj.meta["up_axis"]["axis"] == "y" and obj.meta["up_axis"]["how"].startswith("auto: 3 parts stand along Y")
    ext = np.ptp(np.concatenate([p.mesh.vertices for p in obj.parts]), axis=0)
    np.testing.assert_allclose(ext, [W, W, H], atol=2e-3)  # standing: 0.094 tall
    forced = load_object(d, up_axis="z")
    assert forced.meta["up_axis"] == {"axis": "z", "how": "--up-axis"}
    np.testing.assert_allclose(
        np.ptp(np.concatenate([p.mesh.vertices for p in forced.parts]), axis=0), [W, H, W], atol=2e-3
    )
    m = write_object(tmp_path, "stool-meta", y_up_stool(), meta={"up_axis": "z"})
    assert load_object(m, up_axis="y").meta["up_axis"] == {"axis": "z", "how": "meta.json up_axis"}
    a = write_object(tmp_path, "stool-auto", y_up_stool(), meta={"up_axis": "auto"})
    assert load_object(a, up_axis="z").meta["up_axis"]["axis"] == "y"
    with pytest.raises(ValueError, match="up_axis must be one of"):
        load_object(d, up_axis="x")


def test_aw_prepare_folder_stands_y_up_furniture_and_says_so(tmp_path, capsys):
    src = tmp_path / "src"
    write_object(src, "stool", y_up_stool())
    write_object(src, "square_table", y_up_square_table())
    write_object(src, "z_table", z_up(y_up_square_table()))
    out = tmp_path / "suite"
    assert main(["folder", str(src), "--out", str(out), "--jobs", "1", "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "stool: up axis Y (auto: 3 parts stand along Y, 0 along Z, and it rests stably on its base with Y up)" in err
    assert "square_table: up axis Y (auto: 4 parts stand along Y" in err
    assert "z_table: up axis Z (auto: 0 parts stand along Y, 4 along Z; kept Z)" in err
    for t in read_manifest(out).tasks:  # every assembled target stands 0.094 tall, 0.163 wide
        task_dir, targets_path = suite_paths(out, t.task_id)
        task, targets = read_task(task_dir), read_targets(targets_path)
        v = np.concatenate(
            [
                apply_pose(np.asarray(targets.parts[p.id].pose), m.vertices)
                for p, m in zip(task.parts, load_task_meshes(task), strict=True)
            ]
        )
        ext = np.ptp(v, axis=0)
        assert ext[2] == pytest.approx(ext[0] * H / W, rel=0.03) and ext[1] == pytest.approx(ext[0], rel=0.03), (
            t.task_id
        )
    assert (
        main(["folder", str(src), "--out", str(tmp_path / "lying"), "--up-axis", "z", "--jobs", "1", "--no-progress"])
        == 0
    )
    assert "stool: up axis Z (--up-axis)" in capsys.readouterr().err
