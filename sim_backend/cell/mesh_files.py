"""A declared part's mesh file (STL, OBJ or PLY, in mm) made into the simulated cell's part.

``trimesh`` reads the file and judges it: a file that is missing, unreadable, empty, not a
closed surface (non-manifold or open), inside out beyond repair or of an absurd size is
refused with one line naming the key, before the physics engine sees it. The part is placed
as it lies in the file, z up: its footprint's centre (the middle of its bounds in x and y)
over the part frame's origin, its lowest point on the table. The collision shape is the
mesh's convex hull where the mesh is convex, else a convex decomposition by PyBullet's V-HACD
(``p.vhacd``), so the jaws meet the part's own faces and not a hull over a concave part's
inner corner.
"""

from __future__ import annotations

import io
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drivers.core.errors import ConfigError
from drivers.core.files import FileReadError, read_regular_file
from sim_backend.cell.meshes import BODY_U, Mesh
from sim_backend.cell.pybullet_quiet import p, silenced

FORMATS = (".stl", ".obj", ".ply")
MIN_SIZE_MM = 3.0  # smaller than this the camera sees a few pixels and the jaws miss it
MAX_SIZE_MM = 200.0  # larger than this the part leaves the hand camera's view
MAX_MESH_BYTES = 64 << 20  # a part's mesh is at most a few MB
MAX_TRIANGLES = 200_000  # a part's mesh with more slows every rendered frame
CONVEX_TOLERANCE_MM = 0.01  # a vertex this far outside a face's plane leaves the mesh convex


@dataclass(frozen=True)
class LoadedMesh:
    """A mesh file made ready for the cell.

    mesh: the visual mesh (mm, part frame, one colour, flat-shaded); hulls_obj: OBJ text of
    the convex pieces of a concave mesh (mm, part frame; None: the mesh is convex, its hull
    is the collision shape); pieces: how many convex pieces the collision shape has.
    """

    mesh: Mesh
    hulls_obj: str | None
    pieces: int


def load_part_mesh(path: str, scale: float, key: str) -> LoadedMesh:
    """Read, check and place the mesh file ``path`` (its coordinates times ``scale`` are mm).

    Args:
        key: the config key naming the file, for messages (``parts.bracket.mesh``).

    Raises:
        ConfigError: one line starting with ``key``: the file is missing or unreadable, not an
            STL, OBJ or PLY mesh, empty, not a closed surface, of no volume, or over
            MAX_SIZE_MM or under MIN_SIZE_MM across.
    """
    import trimesh

    where = f"{key}: {path}"
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        raise ConfigError(f"{where}: not an STL, OBJ or PLY file (by its name)")
    try:
        raw = read_regular_file(path, MAX_MESH_BYTES)
    except FileNotFoundError:
        raise ConfigError(f"{where}: no such file") from None
    except FileReadError as exc:
        raise ConfigError(f"{where}: {exc}") from None
    except OSError as exc:
        raise ConfigError(f"{where}: cannot read: {exc.strerror or exc}") from None
    if not raw.strip():
        raise ConfigError(f"{where}: the file is empty")
    try:
        with silenced():
            loaded = trimesh.load(io.BytesIO(raw), file_type=suffix[1:], force="mesh")
    except Exception as exc:  # noqa: BLE001 - any parser error is one bad file
        detail = " ".join(str(exc).split())[:120]
        raise ConfigError(f"{where}: not a readable {suffix[1:].upper()} mesh ({detail})") \
            from None
    faces = getattr(loaded, "faces", None)
    if faces is None or len(faces) == 0:
        raise ConfigError(f"{where}: holds no triangles")
    if len(faces) > MAX_TRIANGLES:
        raise ConfigError(f"{where}: {len(faces)} triangles, over {MAX_TRIANGLES}: simplify it")
    mesh = loaded.copy()
    mesh.apply_scale(scale)
    if not np.all(np.isfinite(mesh.vertices)):
        raise ConfigError(f"{where}: holds a coordinate that is not a finite number")
    size = float(np.ptp(mesh.vertices, axis=0).max())
    hint = "" if scale != 1.0 else " (a file in metres or inches needs scale)"
    if size > MAX_SIZE_MM:
        raise ConfigError(f"{where}: {size:.4g} mm across, over the {MAX_SIZE_MM:g} mm a part "
                          f"may measure{hint}")
    if size < MIN_SIZE_MM:
        raise ConfigError(f"{where}: {size:.4g} mm across, under the {MIN_SIZE_MM:g} mm a part "
                          f"must measure{hint}")
    if not mesh.is_watertight:
        raise ConfigError(f"{where}: not a closed surface (non-manifold or open: an edge not "
                          "shared by exactly two triangles); the collision shape needs a "
                          "closed one")
    if not mesh.is_winding_consistent:
        raise ConfigError(f"{where}: its triangles face inwards and outwards in turn; the "
                          "collision shape needs them wound one way")
    if mesh.volume < 0.0:
        mesh.invert()
    if mesh.volume <= 1e-6 * size ** 3:
        raise ConfigError(f"{where}: encloses no volume")
    lo, hi = mesh.bounds
    mesh.apply_translation([-(lo[0] + hi[0]) / 2.0, -(lo[1] + hi[1]) / 2.0, -lo[2]])
    vertices = np.asarray(mesh.vertices, dtype=float)
    triangles = np.asarray(mesh.faces, dtype=np.int64)
    visual = _flat_shaded(vertices, triangles)
    if is_convex(vertices, triangles):
        return LoadedMesh(visual, None, 1)
    hulls = convex_pieces(vertices, triangles, where)
    return LoadedMesh(visual, hulls, hulls.count("\no ") + hulls.startswith("o "))


def _flat_shaded(vertices: np.ndarray, triangles: np.ndarray) -> Mesh:
    """One vertex per triangle corner, each with its triangle's normal: sharp edges read as
    edges in the hand camera's image, as on the built-in parts."""
    corners = vertices[triangles].reshape(-1, 3)
    v0, v1, v2 = (vertices[triangles[:, i]] for i in range(3))
    normals = np.cross(v1 - v0, v2 - v0)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    n = len(corners)
    return Mesh(corners, np.repeat(normals, 3, axis=0), np.tile([BODY_U, 0.5], (n, 1)),
                np.arange(n, dtype=np.int32).reshape(-1, 3))


def is_convex(vertices: np.ndarray, triangles: np.ndarray,
              tolerance_mm: float = CONVEX_TOLERANCE_MM) -> bool:
    """Whether no vertex lies outside any triangle's plane (by more than ``tolerance_mm``)."""
    v0, v1, v2 = (vertices[triangles[:, i]] for i in range(3))
    normals = np.cross(v1 - v0, v2 - v0)
    lengths = np.linalg.norm(normals, axis=1)
    keep = lengths > 1e-9
    normals, v0 = normals[keep] / lengths[keep, None], v0[keep]
    offsets = np.einsum("ij,ij->i", normals, v0)
    for start in range(0, len(normals), 2048):
        heights = vertices @ normals[start:start + 2048].T - offsets[start:start + 2048]
        if heights.max() > tolerance_mm:
            return False
    return True


def convex_pieces(vertices: np.ndarray, triangles: np.ndarray, where: str) -> str:
    """The OBJ text of a convex decomposition of a closed mesh (mm), by PyBullet's V-HACD.

    Raises:
        ConfigError: the decomposition gave no pieces.
    """
    with tempfile.TemporaryDirectory(prefix="finepos-vhacd-") as tmp:
        src, out, log = (Path(tmp) / name for name in ("part.obj", "hulls.obj", "vhacd.log"))
        lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices]
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in triangles]
        src.write_text("\n".join(lines) + "\n", encoding="utf-8")
        with silenced():
            p.vhacd(str(src), str(out), str(log))
        text = out.read_text(encoding="utf-8") if out.exists() else ""
    if "\nf " not in text:
        raise ConfigError(f"{where}: the convex decomposition of this concave mesh failed")
    return text


SYMMETRY_ORDERS = (12, 10, 8, 6, 5, 4, 3, 2)  # the turns a part's symmetry is looked for at
SYMMETRY_TOLERANCE_MM = 0.05


def rotational_symmetry(vertices_mm: np.ndarray,
                        tolerance_mm: float = SYMMETRY_TOLERANCE_MM) -> int:
    """The largest k of SYMMETRY_ORDERS for which a turn of 360/k deg about the part frame's
    z axis maps every vertex onto a vertex (within ``tolerance_mm``), else 1."""
    points = np.unique(np.round(np.asarray(vertices_mm, dtype=float), 4), axis=0)
    for k in SYMMETRY_ORDERS:
        a = 2.0 * np.pi / k
        turn = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0],
                         [0.0, 0.0, 1.0]])
        if _all_near(points @ turn.T, points, tolerance_mm):
            return k
    return 1


def _all_near(moved: np.ndarray, points: np.ndarray, tolerance_mm: float) -> bool:
    """Whether every moved point lies within ``tolerance_mm`` of one of ``points``."""
    for start in range(0, len(moved), 1024):
        chunk = moved[start:start + 1024]
        d2 = ((chunk[:, None, :] - points[None, :, :]) ** 2).sum(axis=2)
        if d2.min(axis=1).max() > tolerance_mm ** 2:
            return False
    return True
