"""Mesh loading (aw.meshes) and the assembled-object container (aw.assembly)."""

import numpy as np
import pytest
import trimesh

from aw.assembly import AssembledObject, SourcePart, y_up_to_z_up
from aw.formats import FormatError, Task, TaskPart, read_task, write_task
from aw.meshes import load_mesh, load_task_meshes


def test_load_mesh_keeps_vertex_order(tmp_path):
    path = tmp_path / "tri.obj"
    path.write_text("v 0 0 0\nv 2 0 0\nv 0 3 0\nv 9 9 9\nf 1 2 3\nf 1 3 4\n")
    m = load_mesh(path)
    np.testing.assert_array_equal(m.vertices, [[0, 0, 0], [2, 0, 0], [0, 3, 0], [9, 9, 9]])
    assert m.faces.tolist() == [[0, 1, 2], [0, 2, 3]]


@pytest.mark.parametrize(
    "content,problem",
    [
        (None, "mesh file not found"),
        ("v 0 0 0\nv 1 0 0\n", "no triangles"),
        ("", "no triangles"),
        ("v 0 0 0\nv 1e308 0 0\nv 0 1 0\nf 1 2 3\n", "vertex coordinates beyond +-1e+06"),
    ],
)
def test_load_mesh_errors_name_the_file(tmp_path, content, problem):
    path = tmp_path / "part.obj"
    if content is not None:
        path.write_text(content)
    with pytest.raises(FormatError) as info:
        load_mesh(path)
    assert info.value.path == path and problem in info.value.problem


def test_load_mesh_with_a_latin1_comment(tmp_path):
    """A non-UTF-8 byte in a comment (exporters write Latin-1) is decoded, not refused."""
    path = tmp_path / "part.obj"
    path.write_bytes(
        "# Exportiert von Bl\u00e9nder, Gr\u00f6\u00dfe 1\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n".encode("latin-1")
    )
    with pytest.raises(UnicodeDecodeError):
        path.read_bytes().decode("utf-8")
    m = load_mesh(path)
    assert m.vertices.tolist() == [[0, 0, 0], [1, 0, 0], [0, 1, 0]] and m.faces.tolist() == [[0, 1, 2]]


def test_load_task_meshes_in_part_order(tmp_path):
    d = tmp_path / "t"
    (d / "parts").mkdir(parents=True)
    trimesh.creation.box([1, 1, 1]).export(d / "parts" / "a.obj")
    trimesh.creation.box([2, 2, 2]).export(d / "parts" / "b.obj")
    write_task(
        d,
        Task(
            task_id="t",
            source="s",
            dataset="d",
            object_id="o",
            prompt="x",
            parts=[TaskPart(id="p02", mesh="parts/b.obj"), TaskPart(id="p01", mesh="parts/a.obj")],
        ),
    )
    meshes = load_task_meshes(read_task(d))
    assert [round(float(m.extents[0])) for m in meshes] == [2, 1]


def test_y_up_to_z_up_is_a_proper_rotation():
    m = trimesh.Trimesh([[0, 1, 0], [1, 0, 0], [0, 0, 1]], [[0, 1, 2]], process=False)
    out = y_up_to_z_up(m)
    np.testing.assert_array_equal(out.vertices, [[0, 0, 1], [1, 0, 0], [0, -1, 0]])  # +Y becomes +Z
    # Orientation kept: the face normal rotates with the vertices (no mirror).
    r = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]])
    np.testing.assert_allclose(out.face_normals[0], r @ m.face_normals[0], atol=1e-12)


def test_assembled_object_validation():
    box = trimesh.creation.box()
    obj = AssembledObject("o", "partnet", "synthetic", "chair", [SourcePart("a", box), SourcePart("b", box.copy())])
    assert obj.n_parts == 2
    with pytest.raises(ValueError, match="no parts"):
        AssembledObject("o", "s", "d", "c", [])
    with pytest.raises(ValueError, match="unique"):
        AssembledObject("o", "s", "d", "c", [SourcePart("a", box), SourcePart("a", box)])
    bad = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, np.nan, 0]], [[0, 1, 2]], process=False)
    with pytest.raises(ValueError, match="non-finite"):
        AssembledObject("o", "s", "d", "c", [SourcePart("a", bad)])
    with pytest.raises(ValueError, match="empty"):
        AssembledObject("o", "s", "d", "c", [SourcePart("a", trimesh.Trimesh())])
