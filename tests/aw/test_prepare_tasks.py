"""Writing tasks: byte-identical output, paired conditions, references, what stays hidden."""

from __future__ import annotations

import numpy as np
import orjson
import pytest
import trimesh
from PIL import Image
from prepare_helpers import stool

from aw.formats import read_targets, read_task
from aw.formats.suite import suite_paths
from aw.meshes import load_mesh
from aw.prepare import prepare_object, standardize, write_prepared
from aw.prepare.objfile import obj_bytes
from aw.prepare.references import manual_steps
from aw.prompt import task_prompt
from aw.render import BACKGROUND_COLOR
from aw.sources.synthetic import generate_object


def _tree(root) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def paired(tmp_path_factory):
    suite = tmp_path_factory.mktemp("paired")
    obj = generate_object("partnet", 0)
    entries = prepare_object(obj, suite, ["none", "image"])
    return suite, obj, entries


def test_same_input_and_seed_give_byte_identical_tasks(paired, tmp_path):
    suite, obj, _ = paired
    prepare_object(generate_object("partnet", 0), tmp_path, ["none", "image"])
    assert _tree(tmp_path) == _tree(suite)
    other = tmp_path / "seed1"
    prepare_object(obj, other, ["none"], seed=1)
    a = _tree(suite / "tasks" / "partnet-chair_000-none")
    b = _tree(other / "tasks" / "partnet-chair_000-none")
    assert a.keys() == b.keys() and a != b


def test_paired_conditions_share_geometry_layout_and_object(paired):
    suite, obj, entries = paired
    assert [e.condition for e in entries] == ["none", "image"]
    assert {e.object_id for e in entries} == {obj.object_id}
    (none_dir, none_t), (img_dir, img_t) = (suite_paths(suite, e.task_id) for e in entries)
    none, img = read_task(none_dir), read_task(img_dir)
    assert none.part_ids == img.part_ids
    for pid in none.part_ids:
        assert none.mesh_path(pid).read_bytes() == img.mesh_path(pid).read_bytes()
    assert read_targets(none_t).parts == read_targets(img_t).parts
    assert none.references == [] and img.references == ["references/01.png"]
    assert none.prompt == task_prompt("none") and img.prompt == task_prompt("image")


def test_image_reference_is_a_neutral_picture_of_the_assembly(paired):
    suite, _, entries = paired
    img_dir, _ = suite_paths(suite, entries[1].task_id)
    im = np.asarray(Image.open(img_dir / "references" / "01.png").convert("RGB")).astype(float)
    assert im.shape == (768, 1024, 3)
    bg = np.array(BACKGROUND_COLOR) * 255
    assert (np.abs(im - bg).sum(axis=2) > 30).mean() > 0.05  # something is drawn
    # neutral shades only: no saturated part colours that could identify task parts
    sat = im.max(axis=2) - im.min(axis=2)
    assert np.percentile(sat, 99) < 40


def test_task_dir_holds_no_answers(paired):
    suite, obj, entries = paired
    task_dir, targets_path = suite_paths(suite, entries[0].task_id)
    assert targets_path.parent == suite / "targets" and not targets_path.is_relative_to(task_dir)
    files = _tree(task_dir)
    assert set(files) == {"task.json"} | {f"parts/p{k:02d}.obj" for k in range(1, obj.n_parts + 1)}
    text = files["task.json"].decode()
    for secret in ["pose", "target", "scale", "equivalence"] + [p.name for p in obj.parts]:
        assert secret not in orjson.loads(files["task.json"]).keys()
    for p in obj.parts:
        assert f'"{p.name}"' not in text
    # mesh files carry geometry only
    assert all(line[:2] in ("v ", "f ", "# ") for line in files["parts/p01.obj"].decode().splitlines())


def test_manual_pages_one_per_step(tmp_path):
    obj = stool()
    (entry,) = prepare_object(obj, tmp_path, ["manual"])
    task = read_task(suite_paths(tmp_path, entry.task_id)[0])
    assert task.references == ["references/01.png", "references/02.png", "references/03.png"]
    pages = [np.asarray(Image.open(p).convert("RGB")) for p in task.reference_paths()]
    assert all(p.shape == (480, 640, 3) for p in pages)
    assert not np.array_equal(pages[0], pages[1]) and not np.array_equal(pages[1], pages[2])
    # the newly added parts are highlighted in orange on every page
    for p in pages:
        orange = (p[..., 0] > 180) & (p[..., 1] > 70) & (p[..., 1] < 150) & (p[..., 2] < 80)
        assert orange.sum() > 50


def test_manual_steps_from_meta_and_default():
    prep = standardize(stool())
    assert manual_steps(prep) == [[1, 2, 3], [4], [0]]
    plain = stool()
    plain.meta = {}
    assert manual_steps(standardize(plain)) == [[0], [1], [2], [3], [4]]
    bad = stool()
    bad.meta = {"steps": [["seat", "ghost"]]}
    with pytest.raises(ValueError, match="unknown parts"):
        manual_steps(standardize(bad))


def test_provided_references_are_copied(tmp_path):
    obj = stool()
    ref = tmp_path / "photo.jpg"
    Image.new("RGB", (32, 24), (200, 10, 10)).save(ref)
    obj.references = {"image": [ref]}
    (entry,) = prepare_object(obj, tmp_path / "suite", ["image"])
    out = suite_paths(tmp_path / "suite", entry.task_id)[0] / "references" / "01.png"
    with Image.open(out) as im:
        assert im.format == "PNG" and im.size == (32, 24)


def test_write_prepared_rejects_inconsistent_requests(tmp_path):
    prep = standardize(stool())
    with pytest.raises(ValueError, match="condition"):
        write_prepared(prep, tmp_path, "t", "sketch")
    with pytest.raises(ValueError, match="takes no references"):
        write_prepared(prep, tmp_path, "t", "none", [Image.new("RGB", (4, 4))])
    with pytest.raises(ValueError, match="needs at least one"):
        write_prepared(prep, tmp_path, "t", "image", [])
    with pytest.raises(ValueError, match="conditions"):
        prepare_object(stool(), tmp_path, [])


def test_obj_text_is_fixed_format_and_round_trips(tmp_path):
    mesh = trimesh.Trimesh([[0.0, -1e-12, 1.0 / 3.0], [1.0, 0.0, 0.0], [0.0, 1.0, -2.5]], [[0, 1, 2]], process=False)
    text = obj_bytes(mesh).decode()
    assert "v 0.000000000 0.000000000 0.333333333\n" in text  # -0 written as 0
    assert text.endswith("f 1 2 3\n")
    path = tmp_path / "m.obj"
    path.write_text(text)
    back = load_mesh(path)
    np.testing.assert_allclose(back.vertices, mesh.vertices, atol=5e-10)
    np.testing.assert_array_equal(back.faces, mesh.faces)
