"""The parts' registry and meshes: symmetry kappa, grasp data, shapes that look like the parts."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drivers.core.pose import rot_z
from sim_backend.cell.meshes import DARK_U_START, Mesh
from sim_backend.cell.objects import PARTS


def _max_nearest_distance_mm(a: np.ndarray, b: np.ndarray) -> float:
    """Largest distance from a point of ``a`` to its nearest point of ``b``."""
    worst = 0.0
    for chunk in np.array_split(a, max(1, len(a) // 500)):
        d = np.linalg.norm(chunk[:, None, :] - b[None, :, :], axis=-1).min(axis=1)
        worst = max(worst, float(d.max()))
    return worst


def _volume_mm3(mesh: Mesh) -> float:
    v, t = mesh.vertices_mm, mesh.triangles
    return float(np.einsum("ij,ij->i", v[t[:, 0]], np.cross(v[t[:, 1]], v[t[:, 2]])).sum() / 6)


def test_registry():
    assert {k: s.kappa for k, s in PARTS.items()} == {"cube": 4, "nut": 6, "ledge": 2, "screw": 1}
    for kind, spec in PARTS.items():
        assert spec.kind == kind
        assert 0 < spec.grasp_width_mm < 40.0, "must fit the open gripper"
        assert 0 < spec.grip_below_top_mm < spec.height_mm
        assert spec.height_mm - spec.grip_below_top_mm >= 3.0, "fingertips clear the table"


@pytest.mark.parametrize("kind", sorted(PARTS))
def test_meshes_are_well_formed(kind):
    mesh = PARTS[kind].mesh
    assert np.isfinite(mesh.vertices_mm).all()
    np.testing.assert_allclose(np.linalg.norm(mesh.normals, axis=1), 1.0, atol=1e-6)
    assert mesh.triangles.min() >= 0 and mesh.triangles.max() < len(mesh.vertices_mm)
    assert mesh.bounds_mm()[0][2] == pytest.approx(0.0, abs=1e-6), "rests on the table"
    assert _volume_mm3(mesh) > 0, "triangles face outwards"


@pytest.mark.parametrize("kind", sorted(PARTS))
def test_kappa_is_the_parts_symmetry(kind):
    spec = PARTS[kind]
    v = spec.mesh.vertices_mm
    turned = v @ rot_z(2 * math.pi / spec.kappa).T
    assert _max_nearest_distance_mm(turned, v) < 0.05
    if spec.kappa < 6:  # and no finer symmetry than kappa
        finer = v @ rot_z(2 * math.pi / (2 * spec.kappa)).T
        assert _max_nearest_distance_mm(finer, v) > 1.0


def test_the_cube_looks_like_the_toy_cube():
    spec = PARTS["cube"]
    mesh = spec.mesh
    lo, hi = mesh.bounds_mm()
    np.testing.assert_allclose(hi - lo, [30.0, 30.0, 30.0], atol=1e-6)
    # Widely rounded edges: the corners are well inside the sharp box's corners.
    centred = mesh.vertices_mm - [0.0, 0.0, 15.0]
    assert np.linalg.norm(centred, axis=1).max() < 15.0 * math.sqrt(3) - 4.0
    # A dark screw hole in the middle of every face: the faces look like rings.
    dark = mesh.uvs[:, 0] >= DARK_U_START
    for axis in range(3):
        for sign in (1.0, -1.0):
            off_axis = np.linalg.norm(np.delete(centred, axis, axis=1), axis=1)
            hole = dark & (centred[:, axis] * sign > 3.0) & (off_axis < 5.6)
            rim = (~dark) & (centred[:, axis] * sign > 14.9) & (off_axis < 5.6)
            assert hole.sum() > 20 and rim.sum() <= 32, f"face {sign:+g} axis {axis}"
    assert _volume_mm3(mesh) < 30.0**3 * 0.93


def test_the_nut_is_hexagonal_with_a_hole():
    v = PARTS["nut"].mesh.vertices_mm
    radius = np.hypot(v[:, 0], v[:, 1])
    assert radius.max() == pytest.approx(12.0 * 2 / math.sqrt(3), rel=1e-3)  # across corners
    assert np.abs(v[:, 1]).max() == pytest.approx(12.0, abs=1e-6)  # flats face the jaws
    assert radius.min() == pytest.approx(5.5, abs=1e-6)


def test_the_ledge_has_three_holes_and_round_ends():
    mesh = PARTS["ledge"].mesh
    dark = mesh.vertices_mm[mesh.uvs[:, 0] >= DARK_U_START]
    centres = sorted({round(x / 25.0) for x in dark[:, 0]})
    assert centres == [-1, 0, 1]
    lo, hi = mesh.bounds_mm()
    assert hi[0] - lo[0] == pytest.approx(2 * 25.0 + 22.0)


def test_the_screw_has_a_round_slotted_head_and_a_thread():
    spec = PARTS["screw"]
    assert spec.grasp_width_mm == pytest.approx(11.0)
    mesh = spec.mesh
    assert (mesh.uvs[:, 0] >= DARK_U_START).sum() > 10, "the slot"
    near_grasp = mesh.vertices_mm[np.abs(mesh.vertices_mm[:, 0]) < 6.0]
    # Thread: the shank's radius about its axis varies (crests and roots).
    assert np.abs(near_grasp[:, 1]).max() == pytest.approx(5.5, abs=1e-6)
    assert len(spec.geometry.cylinders) == 2
