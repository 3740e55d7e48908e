"""A declared part's mesh file: read, checked, placed and given a collision shape fit for
grasping; a bad file gets one line naming the key, never a physics crash."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from drivers.core.errors import ConfigError
from drivers.core.parts import PARTS, Part
from sim_backend.cell import mesh_files
from sim_backend.cell.objects import spec_for

KEY = "parts.bracket.mesh"


def _l_bracket() -> trimesh.Trimesh:
    """An L-shaped prism (concave), 40 x 12 x 30 mm, built as one closed surface."""
    outline = np.array([[0, 0], [40, 0], [40, 6], [6, 6], [6, 30], [0, 30]], float)  # x, z
    n = len(outline)
    front = np.c_[outline[:, 0], np.zeros(n), outline[:, 1]]
    back = np.c_[outline[:, 0], np.full(n, 12.0), outline[:, 1]]
    vertices = np.vstack([front, back])
    faces = [[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5]]  # the L's face, fanned from a corner
    faces += [[n + c, n + b, n + a] for a, b, c in faces]
    for i in range(n):
        j = (i + 1) % n
        faces += [[i, n + i, n + j], [i, n + j, j]]
    mesh = trimesh.Trimesh(vertices, faces, process=True)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def _write(mesh: trimesh.Trimesh, path) -> str:
    mesh.export(path)
    return str(path)


def test_a_box_is_placed_on_the_table_centred_and_its_hull_is_its_collision_shape(tmp_path):
    box = trimesh.creation.box((20.0, 10.0, 8.0))
    box.apply_translation((100.0, -50.0, 30.0))  # anywhere in the file
    loaded = mesh_files.load_part_mesh(_write(box, tmp_path / "box.stl"), 1.0, KEY)
    lo, hi = loaded.mesh.bounds_mm()
    assert lo == pytest.approx([-10.0, -5.0, 0.0]) and hi == pytest.approx([10.0, 5.0, 8.0])
    assert loaded.hulls_obj is None and loaded.pieces == 1


def test_a_concave_part_is_decomposed_into_convex_pieces(tmp_path):
    bracket = _l_bracket()
    assert bracket.is_watertight and bracket.is_volume
    loaded = mesh_files.load_part_mesh(_write(bracket, tmp_path / "l.obj"), 1.0, KEY)
    assert loaded.hulls_obj is not None and loaded.pieces >= 2
    hull_vertices = np.array([[float(v) for v in line.split()[1:4]]
                              for line in loaded.hulls_obj.splitlines() if line.startswith("v ")])
    lo, hi = loaded.mesh.bounds_mm()
    # The pieces cover the part, not much beyond it (a hull would fill the L's inner corner).
    assert hull_vertices.min(axis=0) == pytest.approx(lo, abs=1.0)
    assert hull_vertices.max(axis=0) == pytest.approx(hi, abs=1.0)


def test_scale_turns_a_file_in_metres_into_millimetres(tmp_path):
    box = trimesh.creation.box((0.02, 0.01, 0.008))
    path = _write(box, tmp_path / "box.ply")
    with pytest.raises(ConfigError, match=r"0.02 mm across, under the 3 mm a part must measure "
                                          r"\(a file in metres or inches needs scale\)$"):
        mesh_files.load_part_mesh(path, 1.0, KEY)
    assert mesh_files.load_part_mesh(path, 1000.0, KEY).mesh.bounds_mm()[1][2] == \
        pytest.approx(8.0)


def _text(path, text: str) -> str:
    path.write_text(text)
    return str(path)


def _open_box(path):
    box = trimesh.creation.box((20.0, 10.0, 8.0))
    return _write(trimesh.Trimesh(box.vertices, box.faces[:-1]), path)


@pytest.mark.parametrize("make, message", [
    (lambda d: str(d / "none.stl"), "no such file"),
    (lambda d: _text(d / "e.stl", ""), "the file is empty"),
    (lambda d: _text(d / "x.ply", "hello"), "not a readable PLY mesh"),
    (lambda d: _text(d / "x.obj", "# nothing\n"), "holds no triangles"),
    (lambda d: str(d / "x.step"), "not an STL, OBJ or PLY file"),
    (lambda d: _open_box(d / "open.stl"), "not a closed surface"),
    (lambda d: _write(trimesh.creation.box((250.0, 10.0, 8.0)), d / "big.stl"),
     "250 mm across, over the 200 mm a part may measure"),
])
def test_a_bad_mesh_file_gets_one_line_naming_the_key(tmp_path, make, message):
    path = make(tmp_path)
    with pytest.raises(ConfigError) as info:
        mesh_files.load_part_mesh(path, 1.0, KEY)
    text = str(info.value)
    assert text.startswith(f"{KEY}: {path}: ") and message in text and "\n" not in text


def test_is_convex_tells_a_box_from_an_l():
    box = trimesh.creation.box((20.0, 10.0, 8.0))
    bracket = _l_bracket()
    assert mesh_files.is_convex(np.asarray(box.vertices), np.asarray(box.faces))
    assert not mesh_files.is_convex(np.asarray(bracket.vertices), np.asarray(bracket.faces))


def test_a_declared_part_without_a_mesh_or_with_an_unknown_material_is_refused():
    pin = Part("pin", 2, 6.0, 5.0, 9.0, 3.0, "wood", (1.0, 0.0, 0.0))
    with pytest.raises(ConfigError, match=r"^parts.pin.mesh: the simulated cell needs"):
        spec_for(pin)
    with pytest.raises(ConfigError, match=r"^parts.pin.material: the simulated cell knows"):
        spec_for(Part("pin", 2, 6.0, 5.0, 9.0, 3.0, "glass", (1.0, 0.0, 0.0), "/x.stl"))
    assert spec_for(PARTS["cube"]).height_mm == pytest.approx(30.0, abs=0.5)
