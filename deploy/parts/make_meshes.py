"""Write the example parts' mesh files (deploy/parts/*.stl, *.obj, *.ply) with trimesh.

Example: .venv/bin/python deploy/parts/make_meshes.py

Each part is a prism: a polygon outline swept along one axis, every length in mm, z up,
lying as it lies on the table. ``deploy/parts/example.yaml`` declares them:
  bracket: an L-bracket standing on its long leg (concave: the inner corner), STL;
  wedge: a bar tapering from one end to the other (elongated, no symmetry), OBJ;
  cross: a plus sign, four 10 mm arms (concave; a quarter turn repeats), PLY.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import trimesh

HERE = Path(__file__).resolve().parent


def _area(points: np.ndarray) -> float:
    x, y = points[:, 0], points[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _cross(u: np.ndarray, v: np.ndarray) -> float:
    return float(u[0] * v[1] - u[1] * v[0])


def _ear_clip(points: np.ndarray) -> list[tuple[int, int, int]]:
    """Triangles (counter-clockwise) filling a simple polygon given counter-clockwise."""
    index = list(range(len(points)))
    triangles = []

    def inside(p, a, b, c) -> bool:
        d = [_cross(b - a, p - a), _cross(c - b, p - b), _cross(a - c, p - c)]
        return all(v >= -1e-12 for v in d)

    while len(index) > 3:
        for k in range(len(index)):
            i, j, m = index[k - 1], index[k], index[(k + 1) % len(index)]
            a, b, c = points[i], points[j], points[m]
            if _cross(b - a, c - b) <= 1e-12:
                continue  # a reflex corner is no ear
            others = [points[n] for n in index if n not in (i, j, m)]
            if any(inside(p, a, b, c) for p in others):
                continue
            triangles.append((i, j, m))
            index.pop(k)
            break
        else:
            raise ValueError("not a simple polygon")
    triangles.append(tuple(index))
    return triangles


def prism(outline, length_mm: float, axis: str) -> trimesh.Trimesh:
    """The outline (2D, mm) swept ``length_mm`` along ``axis`` (``z``: the outline is x, y
    and it stands on z = 0; ``y``: the outline is x, z, centred on y = 0)."""
    points = np.asarray(outline, dtype=float)
    if _area(points) < 0:
        points = points[::-1]
    n = len(points)
    caps = _ear_clip(points)
    faces = [(c, b, a) for a, b, c in caps]  # the outline's plane, facing -sweep
    faces += [(n + a, n + b, n + c) for a, b, c in caps]  # the far cap, facing +sweep
    for i in range(n):
        j = (i + 1) % n
        faces += [(i, j, n + j), (i, n + j, n + i)]
    if axis == "z":
        near = np.c_[points, np.zeros(n)]
        far = np.c_[points, np.full(n, length_mm)]
    else:  # sweep along -y so the caps keep their outward winding
        near = np.c_[points[:, 0], np.full(n, length_mm / 2.0), points[:, 1]]
        far = np.c_[points[:, 0], np.full(n, -length_mm / 2.0), points[:, 1]]
    mesh = trimesh.Trimesh(np.vstack([near, far]), np.asarray(faces), process=True)
    if mesh.volume < 0:
        mesh.invert()
    if not (mesh.is_watertight and mesh.is_volume):
        raise ValueError("the prism is not a closed surface")
    return mesh


def bracket() -> trimesh.Trimesh:
    """An L-bracket: a 42 mm leg 8 mm thick on the table, a 22 mm leg standing at one end,
    both 14 mm deep across the jaws."""
    outline = [(0, 0), (42, 0), (42, 8), (8, 8), (8, 22), (0, 22)]  # x, z
    return prism(outline, 14.0, "y")


def wedge() -> trimesh.Trimesh:
    """A 52 mm bar, 18 mm wide at one end and 8 mm at the other, 8 mm high."""
    outline = [(0, -9), (52, -4), (52, 4), (0, 9)]  # x, y
    return prism(outline, 8.0, "z")


def cross() -> trimesh.Trimesh:
    """A plus sign 30 mm across, its four arms 10 mm wide, 8 mm high."""
    a, b = 5.0, 15.0
    outline = [(b, -a), (b, a), (a, a), (a, b), (-a, b), (-a, a), (-b, a), (-b, -a), (-a, -a),
               (-a, -b), (a, -b), (a, -a)]
    return prism(outline, 8.0, "z")


MESHES = {"bracket.stl": bracket, "wedge.obj": wedge, "cross.ply": cross}


def main(out: Path = HERE) -> int:
    for name, make in MESHES.items():
        data = make().export(file_type=name.rsplit(".", 1)[1])
        (out / name).write_bytes(data if isinstance(data, bytes) else data.encode("utf-8"))
        print(f"wrote {out / name}")
    return 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1]) if len(sys.argv) > 1 else HERE))
