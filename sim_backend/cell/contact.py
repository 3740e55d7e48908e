"""Contact model of the wrist sensor: penetration queries and the wrist wrench.

Nothing here is simulated dynamically (the grasp's dynamics are in ``grasp_physics``); the cell
moves the arm kinematically and asks PyBullet for closest points (negative distance =
penetration). Contact force is a spring: ``stiffness *
depth`` along the contact normal, one spring per touching pair of bodies (gripper link or held
part against table, part, occluder or clutter). The wrist sensor sees the springs' forces and
their torques about its measuring point, plus the weight of the gripper and of a held part.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim_backend.cell.pybullet_quiet import p

GRAVITY_M_S2 = 9.81


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
                   tool_rotation: np.ndarray, loads: list[tuple[float, np.ndarray]],
                   motion_dir: np.ndarray | None = None, friction: float = 0.0) -> np.ndarray:
    """(Fx, Fy, Fz [N], Tx, Ty, Tz [N*m]) on the tool, in the tool frame, about the sensor.

    touching: penetrating contacts (depth > 0 pushes); loads: (mass_kg, centre of mass in
    world mm) carried by the tool; motion_dir: the world direction the tool last moved in
    (unit; None: it has not moved): each pressing contact drags against the part of it along
    the contact's surface with ``friction`` times its own spring's force (a finger sliding
    down the side of a part it squeezes feels the part's drag).
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
        if motion_dir is not None and friction > 0.0:
            sliding = motion_dir - float(motion_dir @ c.normal) * c.normal
            norm = float(np.linalg.norm(sliding))
            if norm > 0.1:  # moving along the surface, not just into it
                f = f - friction * stiffness_n_per_mm * c.depth_mm * sliding / norm
        force += f
        torque_nmm += np.cross(c.point_mm - sensor_origin_mm, f)
    for mass_kg, com_mm in loads:
        f = np.array([0.0, 0.0, -mass_kg * GRAVITY_M_S2])
        force += f
        torque_nmm += np.cross(com_mm - sensor_origin_mm, f)
    r = tool_rotation
    return np.concatenate([r.T @ force, r.T @ torque_nmm / 1000.0])
