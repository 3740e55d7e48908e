"""Contact model of the gripper: penetration queries, the wrist wrench, closing the jaws.

Nothing here is simulated dynamically; the cell moves bodies kinematically and asks PyBullet for
closest points (negative distance = penetration). Contact force is a spring: ``stiffness *
depth`` along the contact normal, one spring per touching pair of bodies (gripper link or held
part against table, part, occluder or clutter). The wrist sensor sees the springs' forces and
their torques about its measuring point, plus the weight of the gripper and of a held part.

The jaws close symmetrically by conservative advancement: each step moves the fingers by the
closest distance to the part (a lower bound on the travel before contact, so nothing tunnels);
a finger that touches the part first pushes it along the jaw axis until the other finger
touches too. The part is held when both fingers touch it from the sides.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim_backend.cell.pybullet_quiet import p

GRAVITY_M_S2 = 9.81
TOUCH_MM = 0.05  # closer than this counts as touching
_SIDE_NORMAL = 0.7  # |normal . jaw axis| above this: the finger touches the part's side
_MAX_CLOSING_STEPS = 200


@dataclass(frozen=True)
class Contact:
    """One touching pair: the point on the moving side (mm, world), the unit normal pushing the
    moving side away, the penetration depth (mm, >= 0) and which bodies/links touch."""

    point_mm: np.ndarray
    normal: np.ndarray
    depth_mm: float
    body_a: int
    link_a: int
    body_b: int


def contacts(client_id: int, body_a: int, others: list[int], margin_mm: float = 0.0,
             skip: frozenset[tuple[int, int]] = frozenset()) -> list[Contact]:
    """Pairs of ``body_a`` (any link) with ``others`` closer than ``margin_mm``, merged per
    (link, other body): the deepest depth, the depth-weighted normal and point."""
    out = []
    for other in others:
        pts = p.getClosestPoints(body_a, other, margin_mm / 1000.0, physicsClientId=client_id)
        by_link: dict[int, list] = {}
        for c in pts:
            if (c[3], other) in skip:
                continue
            by_link.setdefault(c[3], []).append(c)
        for link, group in by_link.items():
            depth = np.array([-c[8] * 1000.0 for c in group])
            weights = np.maximum(depth, 1e-6)
            normal = sum(w * np.asarray(c[7]) for w, c in zip(weights, group, strict=True))
            normal = normal / max(np.linalg.norm(normal), 1e-12)
            point = sum(w * np.asarray(c[5]) for w, c in zip(weights, group, strict=True))
            out.append(Contact(point * 1000.0 / weights.sum(), normal, float(depth.max()),
                               body_a, link, other))
    return out


def wrench_in_tool(touching: list[Contact], stiffness_n_per_mm: float, sensor_origin_mm: np.ndarray,
                   tool_rotation: np.ndarray, loads: list[tuple[float, np.ndarray]]) -> np.ndarray:
    """(Fx, Fy, Fz [N], Tx, Ty, Tz [N*m]) on the tool, in the tool frame, about the sensor.

    touching: penetrating contacts (depth > 0 pushes); loads: (mass_kg, centre of mass in
    world mm) carried by the tool.
    """
    force = np.zeros(3)
    torque_nmm = np.zeros(3)
    pressing = [c for c in touching if c.depth_mm > 0.0]
    total_depth = sum(c.depth_mm for c in pressing)
    for c in pressing:
        # The tool is rigid: the spring is the wrist's and the surface's, shared among the
        # touching points in proportion to their depth (two fingers on the table push back
        # as hard as one would).
        f = stiffness_n_per_mm * c.depth_mm * (c.depth_mm / total_depth) * c.normal
        force += f
        torque_nmm += np.cross(c.point_mm - sensor_origin_mm, f)
    for mass_kg, com_mm in loads:
        f = np.array([0.0, 0.0, -mass_kg * GRAVITY_M_S2])
        force += f
        torque_nmm += np.cross(com_mm - sensor_origin_mm, f)
    r = tool_rotation
    return np.concatenate([r.T @ force, r.T @ torque_nmm / 1000.0])


@dataclass(frozen=True)
class ClosingResult:
    """Where the fingers stopped (inner-face offset from the axis, mm) and whether both
    fingers grip the part's sides."""

    offset_mm: float
    gripping: bool


def close_on(client_id: int, robot: int, fingers: tuple[int, int], part: int,
             jaw_axis: np.ndarray, start_offset_mm: float, set_offset, move_part) -> ClosingResult:
    """Close the jaws from ``start_offset_mm`` until they grip ``part`` or meet.

    fingers: (+jaw finger link, -jaw finger link); jaw_axis: world direction of the + finger
    (unit); set_offset(mm) places both fingers; move_part(delta_mm) shifts the part.
    """
    offset = start_offset_mm
    for _ in range(_MAX_CLOSING_STEPS):
        set_offset(offset)
        gaps = [_gap(client_id, robot, link, part, offset + 1.0) for link in fingers]
        touching = [g is not None and g[0] <= TOUCH_MM for g in gaps]
        sides = [g is not None and abs(float(g[1] @ jaw_axis)) > _SIDE_NORMAL for g in gaps]
        if any(t and not s for t, s in zip(touching, sides, strict=True)):
            return ClosingResult(offset, False)  # a finger sits on the part: stalled
        if all(touching):
            return ClosingResult(offset, True)
        free = [g[0] if g is not None else np.inf for g, t in zip(gaps, touching, strict=True)
                if not t]
        if any(touching):
            step = min(free[0] / 2.0, offset)  # one finger pushes the part towards the other
            direction = -jaw_axis if touching[0] else jaw_axis
            move_part(direction * step)
        else:
            step = min(min(free), offset)
        if offset - step <= 1e-9:
            set_offset(0.0)
            return ClosingResult(0.0, False)
        offset -= max(step, TOUCH_MM / 2.0)
    set_offset(offset)
    return ClosingResult(offset, False)


def _gap(client_id: int, robot: int, link: int, part: int,
         search_mm: float) -> tuple[float, np.ndarray] | None:
    """Closest distance (mm) from a finger to the part and the normal pushing the finger away,
    or None when they are farther apart than ``search_mm``."""
    pts = p.getClosestPoints(robot, part, search_mm / 1000.0, linkIndexA=link,
                             physicsClientId=client_id)
    if not pts:
        return None
    c = min(pts, key=lambda c: c[8])
    return c[8] * 1000.0, np.asarray(c[7])
