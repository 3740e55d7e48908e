"""PUMA 260 kinematics from its DH geometry: forward kinematics and analytic inverse kinematics.

Standard DH (a, alpha, d) rows from the hardware notes; joint angles in the course's zero
convention with its joint ranges. Lengths in mm, angles in radians inside the math, degrees at
the interface (``JOINT_LIMITS_DEG``, ``*_deg`` arguments). The arm has a spherical wrist (axes
4, 5, 6 meet at the wrist centre), so the inverse is closed-form: two shoulder, two elbow and two
wrist branches, each joint also tried at +/-360 deg; the solution within the joint limits closest
to the current joint angles wins. Targets with no such solution raise MotionRejectedError.
"""

from __future__ import annotations

import math

import numpy as np

from drivers.core.errors import MotionRejectedError

# (a_mm, alpha_rad, d_mm) per joint, standard DH: T_i = Rz(q_i) Tz(d_i) Tx(a_i) Rx(alpha_i).
DH_ROWS: tuple[tuple[float, float, float], ...] = (
    (0.0, math.pi / 2, 330.2),
    (203.2, 0.0, -63.5),
    (0.0, -math.pi / 2, -63.5),
    (0.0, math.pi / 2, 203.2),
    (0.0, -math.pi / 2, 0.0),
    (0.0, 0.0, 63.5),
)
JOINT_LIMITS_DEG: tuple[tuple[float, float], ...] = (
    (-180.0, 110.0), (-75.0, 240.0), (-235.0, 60.0),
    (-580.0, 40.0), (-30.0, 200.0), (-215.0, 295.0),
)
BASE_HEIGHT_MM = DH_ROWS[0][2]
UPPER_ARM_MM = DH_ROWS[1][0]
FOREARM_MM = DH_ROWS[3][2]
FLANGE_MM = DH_ROWS[5][2]
# Sideways offset of the wrist centre from the plane of joint 1 (shoulder + elbow offsets).
LATERAL_OFFSET_MM = -(DH_ROWS[1][2] + DH_ROWS[2][2])
_LIMITS_RAD = np.radians(np.array(JOINT_LIMITS_DEG))
# Joint-space distance weights when choosing among IK branches (big joints cost more).
_BRANCH_WEIGHTS = np.array([3.0, 3.0, 2.0, 1.0, 1.0, 1.0])
_SINGULAR_SIN = 1e-9
# Slack on joint limits (rad), so poses computed exactly at a limit stay reachable.
_LIMIT_SLACK_RAD = 1e-9


def dh_transform(q_rad: float, a_mm: float, alpha_rad: float, d_mm: float) -> np.ndarray:
    """4x4 homogeneous DH transform Rz(q) Tz(d) Tx(a) Rx(alpha) (mm)."""
    cq, sq = math.cos(q_rad), math.sin(q_rad)
    ca, sa = math.cos(alpha_rad), math.sin(alpha_rad)
    return np.array([[cq, -sq * ca, sq * sa, a_mm * cq],
                     [sq, cq * ca, -cq * sa, a_mm * sq],
                     [0.0, sa, ca, d_mm],
                     [0.0, 0.0, 0.0, 1.0]])


def link_frames(q_rad) -> list[np.ndarray]:
    """Base frame then the frames 1..6 (4x4, mm) for joint angles ``q_rad``."""
    frames = [np.eye(4)]
    for q, (a, alpha, d) in zip(q_rad, DH_ROWS, strict=True):
        frames.append(frames[-1] @ dh_transform(q, a, alpha, d))
    return frames


def flange_transform(q_rad) -> np.ndarray:
    """4x4 pose (mm) of the flange (frame 6; z = flange axis) in the base frame."""
    return link_frames(q_rad)[-1]


def within_limits(q_rad) -> bool:
    q = np.asarray(q_rad, dtype=float)
    return bool(np.all(q >= _LIMITS_RAD[:, 0] - _LIMIT_SLACK_RAD)
                and np.all(q <= _LIMITS_RAD[:, 1] + _LIMIT_SLACK_RAD))


def limit_violations(q_rad) -> list[str]:
    """Human-readable list of joints outside their range (empty when all are inside)."""
    out = []
    for i, (q, (lo, hi)) in enumerate(zip(np.degrees(q_rad), JOINT_LIMITS_DEG, strict=True)):
        if not lo - 1e-7 <= q <= hi + 1e-7:
            out.append(f"joint {i + 1} at {q:.1f} deg not in [{lo:g}, {hi:g}]")
    return out


def _arm_solutions(wrist_mm: np.ndarray) -> list[tuple[float, float, float]]:
    """(q1, q2, q3) for every shoulder/elbow branch placing the wrist centre at ``wrist_mm``."""
    px, py, pz = wrist_mm
    r2 = px * px + py * py
    off = LATERAL_OFFSET_MM
    if r2 < off * off:
        return []
    reach = math.sqrt(r2 - off * off)
    v = pz - BASE_HEIGHT_MM
    out = []
    for u in (reach, -reach):
        q1 = math.atan2(py, px) - math.atan2(off, u)
        dist2 = u * u + v * v
        cos_delta = (dist2 - UPPER_ARM_MM**2 - FOREARM_MM**2) / (2 * UPPER_ARM_MM * FOREARM_MM)
        if abs(cos_delta) > 1.0:
            continue
        for delta in (-math.acos(cos_delta), math.acos(cos_delta)):
            # Equal link lengths: the shoulder angle bisects the wrist direction.
            q2 = math.atan2(v, u) - delta / 2.0
            q3 = delta - math.pi / 2.0
            out.append((q1, q2, q3))
    return out


def _wrist_solutions(r36: np.ndarray, q4_hint: float) -> list[tuple[float, float, float]]:
    """(q4, q5, q6) for both wrist branches with Rz(q4) Ry(-q5) Rz(q6) = r36."""
    s5 = math.hypot(r36[0, 2], r36[1, 2])
    c5 = r36[2, 2]
    if s5 < _SINGULAR_SIN:
        # Axes 4 and 6 aligned: keep q4, put the whole roll into q6.
        q5 = 0.0 if c5 > 0 else math.pi
        roll = math.atan2(r36[1, 0], r36[0, 0])
        q6 = roll - q4_hint if c5 > 0 else q4_hint - roll
        return [(q4_hint, q5, q6)]
    q5 = math.atan2(s5, c5)
    q4 = math.atan2(-r36[1, 2], -r36[0, 2])
    q6 = math.atan2(-r36[2, 1], r36[2, 0])
    return [(q4, q5, q6), (q4 + math.pi, -q5, q6 + math.pi)]


def _wrap_near(q: float, ref: float) -> float:
    """q plus a multiple of 2 pi, as close as possible to ref."""
    return q + 2.0 * math.pi * round((ref - q) / (2.0 * math.pi))


def _nearest_equivalent(q: np.ndarray, seed: np.ndarray) -> np.ndarray | None:
    """``q`` with each joint shifted by a multiple of 2 pi to lie inside its range and as near
    the seed as possible; None when some joint has no such value."""
    options = []
    for j in range(6):
        base = _wrap_near(q[j], seed[j])
        lo, hi = _LIMITS_RAD[j, 0] - _LIMIT_SLACK_RAD, _LIMITS_RAD[j, 1] + _LIMIT_SLACK_RAD
        vals = [v for v in (base, base - 2 * math.pi, base + 2 * math.pi) if lo <= v <= hi]
        if not vals:
            return None
        options.append(min(vals, key=lambda v, s=seed[j]: abs(v - s)))
    return np.array(options)


def inverse_kinematics(flange: np.ndarray, seed_rad) -> np.ndarray:
    """Joint angles (rad) putting the flange at the 4x4 pose ``flange`` (mm).

    Among all closed-form branches, with each joint moved by +/-360 deg where its range allows,
    the solution inside the joint limits nearest to ``seed_rad`` (weighted) is returned.
    Raises MotionRejectedError (with the reason) when no solution respects the limits.
    """
    seed = np.asarray(seed_rad, dtype=float)
    wrist = flange[:3, 3] - FLANGE_MM * flange[:3, 2]
    arm = _arm_solutions(wrist)
    if not arm:
        dist = float(np.linalg.norm(wrist - np.array([0.0, 0.0, BASE_HEIGHT_MM])))
        raise MotionRejectedError(
            f"target out of reach: wrist centre {np.round(wrist, 1).tolist()} mm is {dist:.0f} mm "
            f"from the shoulder (max {UPPER_ARM_MM + FOREARM_MM:.0f} mm)")
    best, best_cost, violations = None, math.inf, []
    for q1, q2, q3 in arm:
        r03 = link_frames([q1, q2, q3, 0.0, 0.0, 0.0])[3][:3, :3]
        r36 = r03.T @ flange[:3, :3]
        for q4, q5, q6 in _wrist_solutions(r36, seed[3]):
            q = np.array([q1, q2, q3, q4, q5, q6])
            cand = _nearest_equivalent(q, seed)
            if cand is None:
                shifted = np.array([_wrap_near(v, s) for v, s in zip(q, seed, strict=True)])
                violations.extend(limit_violations(shifted))
                continue
            cost = float(np.sum(_BRANCH_WEIGHTS * (cand - seed) ** 2))
            if cost < best_cost:
                best, best_cost = cand, cost
    if best is None:
        reasons = sorted(set(violations)) or ["no branch inside the joint limits"]
        raise MotionRejectedError("target outside the joint limits: " + "; ".join(reasons[:3]))
    return best
