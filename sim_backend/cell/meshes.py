"""Procedural triangle meshes of the toy construction-set parts (mm, part frame, z up).

Every builder returns a ``Mesh`` whose triangles wind counter-clockwise seen from outside (the
renderer culls back faces). The ``u`` texture coordinate carries shading: u < 0.5 is the part's
own colour, u in [0.5, 1] darkens towards 1 (the inside of screw holes, the screw's slot), read
through the two-zone texture made by ``sim_backend.cell.textures.part_texture``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

BODY_U = 0.25  # texture u of the plain part colour
DARK_U_START = 0.5  # texture u where the darkening ramp starts (rim of a hole)
DARK_U_END = 0.98  # texture u of the darkest shade (bottom of a hole)
_SEAM_OVERLAP_MM = 0.2


@dataclass(frozen=True)
class Mesh:
    """Vertices (N, 3) mm, unit normals (N, 3), texture coordinates (N, 2), triangles (M, 3)."""

    vertices_mm: np.ndarray
    normals: np.ndarray
    uvs: np.ndarray
    triangles: np.ndarray

    @staticmethod
    def concat(meshes: list[Mesh]) -> Mesh:
        offsets = np.cumsum([0] + [len(m.vertices_mm) for m in meshes[:-1]])
        return Mesh(np.concatenate([m.vertices_mm for m in meshes]),
                    np.concatenate([m.normals for m in meshes]),
                    np.concatenate([m.uvs for m in meshes]),
                    np.concatenate([m.triangles + o for m, o in zip(meshes, offsets, strict=True)]))

    def transformed(self, rotation: np.ndarray, translation_mm) -> Mesh:
        """The mesh moved rigidly: x' = R x + t."""
        r = np.asarray(rotation, dtype=float)
        return Mesh(self.vertices_mm @ r.T + np.asarray(translation_mm, dtype=float),
                    self.normals @ r.T, self.uvs, self.triangles)

    def bounds_mm(self) -> tuple[np.ndarray, np.ndarray]:
        """Lowest and highest vertex coordinates (mm)."""
        return self.vertices_mm.min(axis=0), self.vertices_mm.max(axis=0)


def _grid_triangles(rows: int, cols: int, closed_cols: bool) -> np.ndarray:
    """Triangles of a rows x cols vertex grid (row-major); ``closed_cols`` wraps the columns.

    The winding follows the grid's parametrisation; builders fix it up with
    ``_orient_outward`` (or, for closed surfaces of revolution, as a whole).
    """
    ncols = cols if closed_cols else cols - 1
    r, c = np.meshgrid(np.arange(rows - 1), np.arange(ncols), indexing="ij")
    a = r * cols + c
    b = r * cols + (c + 1) % cols
    d = (r + 1) * cols + c
    e = (r + 1) * cols + (c + 1) % cols
    tris = np.concatenate([np.stack([a, d, b], -1).reshape(-1, 3),
                           np.stack([b, d, e], -1).reshape(-1, 3)])
    return tris.astype(np.int32)


def _orient_outward(mesh: Mesh) -> Mesh:
    """Flip any triangle whose geometric normal disagrees with its vertex normals."""
    v, t = mesh.vertices_mm, mesh.triangles
    geo = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    vn = mesh.normals[t].sum(axis=1)
    flip = np.einsum("ij,ij->i", geo, vn) < 0
    tris = t.copy()
    tris[flip] = tris[flip][:, [0, 2, 1]]
    return Mesh(mesh.vertices_mm, mesh.normals, mesh.uvs, tris)


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


def _body_uv(n: int) -> np.ndarray:
    return np.tile([BODY_U, 0.5], (n, 1))


def _dark_uv(depth_fraction: np.ndarray) -> np.ndarray:
    u = DARK_U_START + (DARK_U_END - DARK_U_START) * np.clip(depth_fraction, 0.0, 1.0)
    return np.stack([u, np.full_like(u, 0.5)], axis=-1)


# -- primitives for the robot (one texture swatch per primitive) --------------------------------

def box(half_mm, u: float) -> Mesh:
    """An axis-aligned box centred on the origin, coloured by texture coordinate ``u``."""
    h = np.asarray(half_mm, dtype=float)
    verts, norms = [], []
    for axis in range(3):
        for sign in (1.0, -1.0):
            n = np.zeros(3)
            n[axis] = sign
            a, b = np.zeros(3), np.zeros(3)
            a[(axis + 1) % 3] = 1.0
            b[(axis + 2) % 3] = 1.0
            corners = [n * h[axis] + (sa * a * h) + (sb * b * h)
                       for sa, sb in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
            verts.extend(corners)
            norms.extend([n] * 4)
    quads = np.arange(24).reshape(6, 4)
    tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]).astype(np.int32)
    mesh = Mesh(np.array(verts), np.array(norms), np.tile([u, 0.5], (24, 1)), tris)
    return _orient_outward(mesh)


def cylinder(radius_mm: float, length_mm: float, u: float, segments: int = 24) -> Mesh:
    """A closed cylinder along z, centred on the origin, coloured by texture coordinate ``u``."""
    phi = np.linspace(0.0, 2.0 * math.pi, segments, endpoint=False)
    ring = np.c_[np.cos(phi), np.sin(phi)] * radius_mm
    z0, z1 = -length_mm / 2.0, length_mm / 2.0
    side = Mesh(np.vstack([np.c_[ring, np.full(segments, z1)], np.c_[ring, np.full(segments, z0)]]),
                np.tile(np.c_[ring / radius_mm, np.zeros(segments)], (2, 1)),
                np.tile([u, 0.5], (2 * segments, 1)), _grid_triangles(2, segments, True))
    caps = []
    for z, up in ((z1, 1.0), (z0, -1.0)):
        verts = np.vstack([[0.0, 0.0, z], np.c_[ring, np.full(segments, z)]])
        k = np.arange(segments)
        tris = np.stack([np.zeros(segments, int), 1 + k, 1 + (k + 1) % segments], -1)
        caps.append(Mesh(verts, np.tile([0.0, 0.0, up], (segments + 1, 1)),
                         np.tile([u, 0.5], (segments + 1, 1)), tris.astype(np.int32)))
    return _orient_outward(Mesh.concat([side, *caps]))


def placed(mesh: Mesh, rotation: np.ndarray | None = None, translation_mm=(0.0, 0.0, 0.0)) -> Mesh:
    """``mesh`` rotated (default: not) and moved to ``translation_mm``."""
    return mesh.transformed(np.eye(3) if rotation is None else rotation, translation_mm)


def grid_plane(min_mm: tuple[float, float], max_mm: tuple[float, float], cell_mm: float,
               uv_per_mm: float) -> Mesh:
    """A horizontal rectangle at z = 0 facing up, split into cells of about ``cell_mm`` (small
    triangles rasterise faster than huge ones clipped at the camera), u/v = x/y * uv_per_mm."""
    nx = max(1, round((max_mm[0] - min_mm[0]) / cell_mm))
    ny = max(1, round((max_mm[1] - min_mm[1]) / cell_mm))
    xs, ys = np.linspace(min_mm[0], max_mm[0], nx + 1), np.linspace(min_mm[1], max_mm[1], ny + 1)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    verts = np.c_[gx.reshape(-1), gy.reshape(-1), np.zeros(gx.size)]
    mesh = Mesh(verts, np.tile([0.0, 0.0, 1.0], (len(verts), 1)), verts[:, :2] * uv_per_mm,
                _grid_triangles(nx + 1, ny + 1, closed_cols=False))
    return _orient_outward(mesh)


# -- the cube: a rounded box with a blind screw hole in the middle of every face ----------------

def _rounded_box_sdf(p: np.ndarray, half_mm: float, radius_mm: float) -> np.ndarray:
    q = np.abs(p) - (half_mm - radius_mm)
    outside = np.linalg.norm(np.maximum(q, 0.0), axis=-1)
    inside = np.minimum(q.max(axis=-1), 0.0)
    return outside + inside - radius_mm


def _rounded_box_normal(p: np.ndarray, half_mm: float, radius_mm: float) -> np.ndarray:
    q = np.abs(p) - (half_mm - radius_mm)
    n = np.maximum(q, 0.0) * np.sign(p)
    flat = np.linalg.norm(n, axis=-1) < 1e-9
    if flat.any():
        axis = np.argmax(q[flat], axis=-1)
        n_flat = np.zeros((int(flat.sum()), 3))
        n_flat[np.arange(len(axis)), axis] = np.sign(p[flat][np.arange(len(axis)), axis])
        n[flat] = n_flat
    return _unit(n)


def _ray_to_surface(directions: np.ndarray, sdf: Callable[[np.ndarray], np.ndarray],
                    far_mm: float) -> np.ndarray:
    """Where rays from the origin leave a convex solid (bisection on the distance function)."""
    lo = np.zeros(len(directions))
    hi = np.full(len(directions), far_mm)
    for _ in range(48):
        mid = 0.5 * (lo + hi)
        inside = sdf(directions * mid[:, None]) < 0.0
        lo = np.where(inside, mid, lo)
        hi = np.where(inside, hi, mid)
    return directions * (0.5 * (lo + hi))[:, None]


def holed_rounded_cube(edge_mm: float, edge_radius_mm: float, hole_radius_mm: float,
                       hole_depth_mm: float, segments: int = 32) -> Mesh:
    """A cube with rounded edges/corners and a blind round hole centred in each of its faces.

    The cube is centred on the origin. Each face is meshed as a ring from the hole's rim out to
    the face's share of the rounded box (found by casting rays from the centre), so the six
    patches meet along the diagonals of the rounded edges. ``segments`` (a multiple of 8) sets
    the angular resolution.
    """
    if segments % 8:
        raise ValueError("segments must be a multiple of 8")
    half = edge_mm / 2.0
    if not hole_radius_mm < half - edge_radius_mm:
        raise ValueError("the hole must fit in the flat part of a face")
    theta = np.linspace(0.0, 2.0 * math.pi, segments, endpoint=False)
    ring = np.stack([np.cos(theta), np.sin(theta)], -1)
    square = ring / np.abs(ring).max(axis=1, keepdims=True)  # the face's edge, in units of half
    flat_end = (half - edge_radius_mm) / half
    # Blend steps from the hole rim (0) to the face edge (1): coarse on the flat, fine on the bend.
    steps = np.concatenate([np.linspace(0.0, 0.3, 2), 0.3 + 0.7 * np.sin(
        np.linspace(0.0, math.pi / 2, 6)[1:]) ** 1.5])
    hole = ring * (hole_radius_mm / half)
    sdf = lambda p: _rounded_box_sdf(p, half, edge_radius_mm)  # noqa: E731
    patches = []
    axes = np.eye(3)
    for axis in range(3):
        for sign in (1.0, -1.0):
            n = axes[axis] * sign
            e1 = axes[(axis + 1) % 3]
            e2 = np.cross(n, e1)
            st = (1.0 - steps)[:, None, None] * hole[None] + steps[:, None, None] * square[None]
            # Points on the flat part lie exactly on the face; cast rays for the rest.
            pts_local = st.reshape(-1, 2)
            dirs = n + pts_local[:, :1] * e1 + pts_local[:, 1:] * e2
            on_flat = np.abs(pts_local).max(axis=1) <= flat_end + 1e-12
            surf = np.empty_like(dirs)
            surf[on_flat] = dirs[on_flat] * half
            surf[~on_flat] = _ray_to_surface(_unit(dirs[~on_flat]), sdf, 2.0 * half)
            normals = _rounded_box_normal(surf, half, edge_radius_mm)
            face = Mesh(surf, normals, _body_uv(len(surf)),
                        _grid_triangles(len(steps), segments, closed_cols=True))
            wall, bottom = _blind_hole(n, e1, e2, half, hole_radius_mm, hole_depth_mm, theta)
            patches.extend([face, wall, bottom])
    return _orient_outward(Mesh.concat(patches))


def _blind_hole(n: np.ndarray, e1: np.ndarray, e2: np.ndarray, face_offset_mm: float,
                radius_mm: float, depth_mm: float, theta: np.ndarray) -> tuple[Mesh, Mesh]:
    """Wall and bottom of a round hole going ``depth_mm`` into a face (normal ``n``)."""
    levels = np.linspace(0.0, 1.0, 3)
    radial = np.cos(theta)[:, None] * e1 + np.sin(theta)[:, None] * e2
    pts = (face_offset_mm - levels[:, None, None] * depth_mm) * n + radius_mm * radial[None]
    wall_n = np.broadcast_to(-radial[None], pts.shape)
    uv = _dark_uv(np.repeat(levels, len(theta)))
    wall = Mesh(pts.reshape(-1, 3), wall_n.reshape(-1, 3).copy(), uv,
                _grid_triangles(len(levels), len(theta), closed_cols=True))
    centre = (face_offset_mm - depth_mm) * n
    rim = centre + radius_mm * radial
    verts = np.vstack([centre, rim])
    k = len(theta)
    tris = np.stack([np.zeros(k, int), 1 + np.arange(k), 1 + (np.arange(k) + 1) % k], -1)
    bottom = Mesh(verts, np.tile(n, (k + 1, 1)), _dark_uv(np.ones(k + 1)), tris.astype(np.int32))
    return wall, bottom


# -- prisms with vertical holes: the nut and the ledge -----------------------------------------

def _radius_on_polygon(theta: np.ndarray, apothem_mm: float, sides: int) -> np.ndarray:
    """Distance from the centre to a regular polygon's edge (flats at angle 0) along theta."""
    sector = 2.0 * math.pi / sides
    local = (theta + sector / 2.0) % sector - sector / 2.0
    return apothem_mm / np.cos(local)


def hex_nut(across_flats_mm: float, thickness_mm: float, hole_radius_mm: float,
            chamfer_mm: float, segments: int = 48) -> Mesh:
    """A hexagonal nut lying flat (base at z = 0), with chamfered corners and a through hole.

    Flats face +/-x. The chamfer is a cone cutting the six corners, as on a real nut: the top and
    bottom faces are discs of the across-flats diameter.
    """
    theta = np.linspace(0.0, 2.0 * math.pi, segments, endpoint=False)
    apothem = across_flats_mm / 2.0
    full = _radius_on_polygon(theta, apothem, 6)
    cut = np.minimum(full, apothem * 0.98)
    c = min(chamfer_mm, thickness_mm / 3.0)
    layers = [(thickness_mm, cut), (thickness_mm - c, full), (c, full), (0.0, cut)]
    return _holed_loft(theta, layers, hole_radius_mm)


def _holed_loft(theta: np.ndarray, layers: list[tuple[float, np.ndarray]],
                hole_radius_mm: float) -> Mesh:
    """A solid with a round through hole on its axis: its outline's radii per layer (top to
    bottom, sampled at ``theta``) joined into the side, ring-shaped top and bottom faces, and
    the hole's wall."""
    ring = np.stack([np.cos(theta), np.sin(theta)], -1)
    k = len(theta)
    parts = []
    # Side: consecutive layers joined; normals from the outline's slope.
    for (z0, r0), (z1, r1) in zip(layers[:-1], layers[1:], strict=True):
        pts = np.stack([np.c_[ring * r0[:, None], np.full(k, z0)],
                        np.c_[ring * r1[:, None], np.full(k, z1)]])
        tang = np.roll(pts[0], -1, axis=0) - np.roll(pts[0], 1, axis=0)
        down = pts[1] - pts[0]
        nrm = _unit(np.cross(tang, down))
        nrm = np.where((np.einsum("ij,ij->i", nrm, np.c_[ring, np.zeros(k)]) < 0)[:, None],
                       -nrm, nrm)
        parts.append(Mesh(pts.reshape(-1, 3), np.vstack([nrm, nrm]), _body_uv(2 * k),
                          _grid_triangles(2, k, closed_cols=True)))
    (z_top, r_top), (z_bot, r_bot) = layers[0], layers[-1]
    for z, r_out, up in ((z_top, r_top, 1.0), (z_bot, r_bot, -1.0)):
        steps = np.linspace(0.0, 1.0, 4)
        rad = (1 - steps)[:, None] * hole_radius_mm + steps[:, None] * r_out[None]
        pts = np.concatenate([np.c_[ring * rr[:, None], np.full(k, z)] for rr in rad])
        parts.append(Mesh(pts, np.tile([0.0, 0.0, up], (len(pts), 1)), _body_uv(len(pts)),
                          _grid_triangles(len(steps), k, closed_cols=True)))
    depth = z_top - z_bot
    levels = np.linspace(0.0, 1.0, 4)
    pts = np.concatenate([np.c_[ring * hole_radius_mm, np.full(k, z_top - lv * depth)]
                          for lv in levels])
    nrm = np.tile(np.c_[-ring, np.zeros(k)], (len(levels), 1))
    # Darkest halfway down a through hole, lighter again towards the other opening.
    shade = 1.0 - np.abs(2.0 * np.repeat(levels, k) - 1.0)
    parts.append(Mesh(pts, nrm, _dark_uv(shade * 0.8), _grid_triangles(len(levels), k, True)))
    return _orient_outward(Mesh.concat(parts))


def holed_ledge(holes: int, pitch_mm: float, width_mm: float, thickness_mm: float,
                hole_radius_mm: float, segments: int = 40) -> Mesh:
    """A flat bar with round ends and ``holes`` through holes along x (base at z = 0).

    The top and bottom faces are made of one ring-shaped cell per hole: from the hole's rim out
    to the cell's border (a pitch x width rectangle, or a half-disc at the two ends).
    """
    theta = np.linspace(0.0, 2.0 * math.pi, segments, endpoint=False) + math.pi / segments
    ring = np.stack([np.cos(theta), np.sin(theta)], -1)
    k = len(theta)
    half_w, half_p = width_mm / 2.0, pitch_mm / 2.0
    centres = (np.arange(holes) - (holes - 1) / 2.0) * pitch_mm
    # Cells overlap their neighbours by a hair so no rasteriser crack shows along the seam.
    with np.errstate(divide="ignore"):
        rect = np.minimum((half_p + _SEAM_OVERLAP_MM) / np.abs(ring[:, 0]),
                          half_w / np.abs(ring[:, 1]))
    parts = []
    for i, cx in enumerate(centres):
        outer = rect.copy()
        for end, sign in ((i == 0, -1.0), (i == holes - 1, 1.0)):
            if end:
                outward = ring[:, 0] * sign > 0
                outer[outward] = half_w
        steps = np.linspace(0.0, 1.0, 4)
        for z, up in ((thickness_mm, 1.0), (0.0, -1.0)):
            rad = (1 - steps)[:, None] * hole_radius_mm + steps[:, None] * outer[None]
            pts = np.concatenate([np.c_[ring * rr[:, None] + [cx, 0.0], np.full(k, z)]
                                  for rr in rad])
            parts.append(Mesh(pts, np.tile([0.0, 0.0, up], (len(pts), 1)), _body_uv(len(pts)),
                              _grid_triangles(len(steps), k, closed_cols=True)))
        # Hole wall, darkest halfway down.
        levels = np.linspace(0.0, 1.0, 3)
        pts = np.concatenate([np.c_[ring * hole_radius_mm + [cx, 0.0],
                                    np.full(k, thickness_mm * (1.0 - lv))] for lv in levels])
        shade = 1.0 - np.abs(2.0 * np.repeat(levels, k) - 1.0)
        parts.append(Mesh(pts, np.tile(np.c_[-ring, np.zeros(k)], (len(levels), 1)),
                          _dark_uv(shade * 0.6), _grid_triangles(len(levels), k, True)))
    parts.append(_stadium_wall((centres[-1] - centres[0]) / 2.0, half_w, thickness_mm, segments))
    return _orient_outward(Mesh.concat(parts))


def _stadium_wall(half_span_mm: float, radius_mm: float, height_mm: float,
                  segments: int) -> Mesh:
    """Vertical side wall of a stadium (two half-discs joined by straight sides)."""
    n_arc = segments // 2 + 1
    arc = np.linspace(-math.pi / 2, math.pi / 2, n_arc)
    right = np.c_[half_span_mm + radius_mm * np.cos(arc), radius_mm * np.sin(arc)]
    left = np.c_[-half_span_mm - radius_mm * np.cos(arc), -radius_mm * np.sin(arc)]
    outline = np.vstack([right, left])  # counter-clockwise
    normals2 = np.vstack([np.c_[np.cos(arc), np.sin(arc)], np.c_[-np.cos(arc), -np.sin(arc)]])
    k = len(outline)
    pts = np.concatenate([np.c_[outline, np.full(k, z)] for z in (height_mm, 0.0)])
    nrm = np.tile(np.c_[normals2, np.zeros(k)], (2, 1))
    return Mesh(pts, nrm, _body_uv(len(pts)), _grid_triangles(2, k, closed_cols=True))


# -- solids of revolution: the round-headed screw -----------------------------------------------

def _vertex_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Area-weighted average of the adjacent triangles' normals."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    face = np.cross(b - a, c - a)
    acc = np.zeros_like(vertices)
    for corner in range(3):
        np.add.at(acc, triangles[:, corner], face)
    return _unit(acc)


def revolved(pieces: list[np.ndarray], segments: int,
             dark: Callable[[np.ndarray], np.ndarray] | None = None) -> Mesh:
    """Surface of revolution about the x axis of a profile given as pieces of (x, r) points.

    The profile runs from one end of the part to the other around its outside, starting and
    ending on the axis (r = 0), so the surface is closed. Consecutive pieces share their end and
    start point; normals are smooth within a piece and crisp between pieces. ``dark(points)``
    optionally returns a darkening value in [0, 1] per vertex (0 = the plain colour).
    """
    phi = np.linspace(0.0, 2.0 * math.pi, segments, endpoint=False)
    cos, sin = np.cos(phi), np.sin(phi)
    parts = []
    for piece in pieces:
        prof = np.asarray(piece, dtype=float)
        n = len(prof)
        r = np.repeat(prof[:, 1], segments)
        pts = np.c_[np.repeat(prof[:, 0], segments), r * np.tile(cos, n), r * np.tile(sin, n)]
        tris = _grid_triangles(n, segments, closed_cols=True)
        shade = dark(pts) if dark is not None else np.zeros(len(pts))
        uv = np.where((shade > 0)[:, None], _dark_uv(shade), _body_uv(len(pts)))
        parts.append(Mesh(pts, _vertex_normals(pts, tris), uv, tris))
    mesh = Mesh.concat(parts)
    # The winding is the same everywhere; make it face away from the axis at the widest ring.
    widest = int(np.argmax(np.hypot(mesh.vertices_mm[:, 1], mesh.vertices_mm[:, 2])))
    radial = mesh.vertices_mm[widest] * [0.0, 1.0, 1.0]
    if float(mesh.normals[widest] @ radial) < 0:
        mesh = Mesh(mesh.vertices_mm, -mesh.normals, mesh.uvs, mesh.triangles[:, [0, 2, 1]])
    return mesh


def round_head_screw(head_radius_mm: float, head_height_mm: float, shank_radius_mm: float,
                     shank_length_mm: float, thread_pitch_mm: float, thread_depth_mm: float,
                     slot_width_mm: float, segments: int = 40) -> Mesh:
    """A round-headed (dome) screw with a slotted head and a coarse thread, axis along +x.

    The dome's apex is at x = -head_height, the underside of the head at x = 0, the tip at
    x = shank_length.
    """
    cap_r = (head_radius_mm**2 + head_height_mm**2) / (2.0 * head_height_mm)
    a = np.linspace(0.0, math.asin(head_radius_mm / cap_r), 14)
    dome = np.c_[-head_height_mm + cap_r * (1.0 - np.cos(a)), cap_r * np.sin(a)]
    underside = np.array([[0.0, head_radius_mm], [0.0, shank_radius_mm]])
    tip_len = 1.5 * thread_depth_mm
    x = np.arange(0.0, shank_length_mm - tip_len, thread_pitch_mm / 4.0)
    phase = (x / thread_pitch_mm) % 1.0
    ridge = 1.0 - np.abs(2.0 * phase - 1.0)  # 0 on a crest, 1 in a root
    thread = np.c_[x, shank_radius_mm - thread_depth_mm * ridge]
    tip = np.array([thread[-1], [shank_length_mm, shank_radius_mm - 1.5 * thread_depth_mm],
                    [shank_length_mm, 0.0]])
    half_slot = slot_width_mm / 2.0

    def slot(points: np.ndarray) -> np.ndarray:
        on_head = points[:, 0] < -0.15 * head_height_mm
        return np.where(on_head & (np.abs(points[:, 1]) < half_slot), 0.9, 0.0)

    return revolved([dome, underside, thread, tip], segments, dark=slot)
