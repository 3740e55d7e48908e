"""The grasp's dynamics: the part as a dynamic body, jaws closing under position and force control.

Everything else in the cell is kinematic (arm moves set the joints; the wrist sensor's forces
come from the spring model in ``contact``). Only where a grasp needs physics does the cell step
PyBullet, and only with this module's helpers:

- ``close_jaws``: both fingers are driven towards each other by PyBullet position motors whose
  force is limited to the gripper's grip force, coupled by a gear constraint (a parallel
  gripper's fingers move together), at a 1 kHz step. The part (dynamic: mass from the
  catalogue, friction with the table and the finger pads) is pushed, turned or tilted by
  whichever finger reaches it first, as physics does; the jaws stop where the part stops them.
- ``hold_test``: the lift, quasi-statically: the table's support is taken away while the
  closed jaws keep squeezing; a part the friction does not hold slides out. A lift at the
  arm's speeds accelerates the part far less than gravity does, so this is the lift's load.
- ``settle``: a released or dropped part falls and comes to rest on the table.

The arm's joints are braked and put back to their pose after every step: only the fingers and
the part move. Figures below are judgements for a small pneumatic parallel gripper with rubber
pads and the wooden parts of a toy construction set.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim_backend.cell.pybullet_quiet import p
from sim_backend.cell.robot_model import ARM_JOINTS, FINGER_LINKS

STEP_S = 1.0 / 1000.0
SOLVER_ITERATIONS = 100
FINGER_MASS_KG = 0.05
FINGER_PAD_FRICTION = 0.8  # rubber pads on wood (judgement)
# Torsional friction of a pad (m): the friction torque about the contact normal per newton of
# grip. A pad grips over an area (about 5 mm radius here): a part held off its centre of mass
# does not pivot about the jaw axis; PyBullet's few contact points alone would let it.
# PyBullet combines two bodies' spinning friction as s_a * mu_b + mu_a * s_b: the pads carry
# it divided by the part's (lateral) friction, the parts and the table carry none.
PAD_SPINNING_FRICTION_M = FINGER_PAD_FRICTION * 0.005
TABLE_FRICTION = 0.5
CLOSING_SPEED_MM_S = 30.0
MAX_CLOSING_S = 0.8
HOLD_TEST_S = 0.25
SLIP_MM = 2.0  # a part that slides this far down the jaws during the hold test is not held
_STILL_MM_S = 0.5
_BRAKE_FORCE = 1e5


@dataclass(frozen=True)
class Jaws:
    """The robot's ids in its client and the gear constraint that couples the fingers."""

    client_id: int
    robot_id: int
    gear_id: int


def setup(client_id: int, robot_id: int, table_id: int, part_friction: float) -> Jaws:
    """Gravity, the step, the fingers' dynamics and their coupling (once per cell);
    ``part_friction``: the grasped part's (for the pads' torsional friction on it)."""
    p.setGravity(0.0, 0.0, -9.81, physicsClientId=client_id)
    p.setPhysicsEngineParameter(fixedTimeStep=STEP_S, numSolverIterations=SOLVER_ITERATIONS,
                                physicsClientId=client_id)
    for link in FINGER_LINKS:
        p.changeDynamics(robot_id, link, mass=FINGER_MASS_KG, lateralFriction=FINGER_PAD_FRICTION,
                         spinningFriction=PAD_SPINNING_FRICTION_M / part_friction,
                         physicsClientId=client_id)
    p.changeDynamics(table_id, -1, lateralFriction=TABLE_FRICTION, physicsClientId=client_id)
    gear = p.createConstraint(robot_id, FINGER_LINKS[0], robot_id, FINGER_LINKS[1], p.JOINT_GEAR,
                              [0.0, 1.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0],
                              physicsClientId=client_id)
    p.changeConstraint(gear, gearRatio=-1.0, erp=0.2, maxForce=1000.0, physicsClientId=client_id)
    return Jaws(client_id, robot_id, gear)


def make_dynamic(client_id: int, body_id: int, mass_kg: float, friction: float) -> None:
    """Give a part its mass and friction (it moves only while the cell steps); the pads'
    torsional friction on it (``PAD_SPINNING_FRICTION_M``) is set on the fingers."""
    p.changeDynamics(body_id, -1, mass=mass_kg, lateralFriction=friction,
                     physicsClientId=client_id)


def _step(jaws: Jaws, q_arm: np.ndarray) -> None:
    cid, robot = jaws.client_id, jaws.robot_id
    p.stepSimulation(physicsClientId=cid)
    for joint, q in zip(ARM_JOINTS, q_arm, strict=True):
        p.resetJointState(robot, joint, float(q), physicsClientId=cid)


def _brake_arm(jaws: Jaws) -> None:
    for joint in ARM_JOINTS:
        p.setJointMotorControl2(jaws.robot_id, joint, p.VELOCITY_CONTROL, targetVelocity=0.0,
                                force=_BRAKE_FORCE, physicsClientId=jaws.client_id)


def finger_offsets_mm(jaws: Jaws) -> tuple[float, float]:
    """Each finger's inner face from the tool axis (mm), as the simulation has them."""
    return tuple(p.getJointState(jaws.robot_id, j, physicsClientId=jaws.client_id)[0] * 1000.0
                 for j in FINGER_LINKS)  # type: ignore[return-value]


def _drive_fingers(jaws: Jaws, target_mm: float, force_n: float) -> None:
    for joint in FINGER_LINKS:
        p.setJointMotorControl2(jaws.robot_id, joint, p.POSITION_CONTROL,
                                targetPosition=target_mm / 1000.0, force=force_n,
                                maxVelocity=CLOSING_SPEED_MM_S / 1000.0,
                                physicsClientId=jaws.client_id)


def close_jaws(jaws: Jaws, q_arm: np.ndarray, grip_force_n: float) -> float:
    """Close the jaws under position control with ``grip_force_n`` as the force limit until
    they stop (on the part, or meeting); returns the mean finger offset (mm)."""
    _brake_arm(jaws)
    _drive_fingers(jaws, 0.0, grip_force_n)
    previous = np.array(finger_offsets_mm(jaws))
    still = 0
    for _ in range(int(MAX_CLOSING_S / STEP_S)):
        _step(jaws, q_arm)
        now = np.array(finger_offsets_mm(jaws))
        speed = float(np.abs(now - previous).max()) / STEP_S
        previous = now
        still = still + 1 if speed < _STILL_MM_S else 0
        if still >= 20 or float(now.mean()) <= 0.01:
            break
    return float(previous.mean())


def touching_fingers(jaws: Jaws, part_id: int) -> tuple[bool, bool]:
    """Whether each finger (+y, -y) is in contact with the part."""
    return tuple(bool(p.getContactPoints(jaws.robot_id, part_id, linkIndexA=link,
                                         physicsClientId=jaws.client_id))
                 for link in FINGER_LINKS)  # type: ignore[return-value]


def hold_test(jaws: Jaws, q_arm: np.ndarray, part_id: int, supports: list[int],
              grip_force_n: float) -> bool:
    """Take the ``supports``' (table, ...) support away from the part for ``HOLD_TEST_S`` while
    the jaws squeeze; whether the part stayed within ``SLIP_MM`` and between both fingers.
    The supports' collisions with the part are restored afterwards."""
    cid = jaws.client_id
    start = np.array(p.getBasePositionAndOrientation(part_id, physicsClientId=cid)[0])
    for body in supports:
        p.setCollisionFilterPair(part_id, body, -1, -1, 0, physicsClientId=cid)
    _brake_arm(jaws)
    _drive_fingers(jaws, 0.0, grip_force_n)
    held = True
    for _ in range(int(HOLD_TEST_S / STEP_S)):
        _step(jaws, q_arm)
        pos = np.array(p.getBasePositionAndOrientation(part_id, physicsClientId=cid)[0])
        if (start[2] - pos[2]) * 1000.0 > SLIP_MM:
            held = False
            break
    held = held and all(touching_fingers(jaws, part_id))
    for body in supports:
        p.setCollisionFilterPair(part_id, body, -1, -1, 1, physicsClientId=cid)
    return held


def settle(jaws: Jaws, q_arm: np.ndarray, part_id: int, finger_offset_mm: float,
           max_s: float = 1.5) -> None:
    """Step, the fingers held at ``finger_offset_mm``, until the part comes to rest (or
    ``max_s`` passes)."""
    cid = jaws.client_id
    _brake_arm(jaws)
    _drive_fingers(jaws, finger_offset_mm, 50.0)
    still = 0
    for _ in range(int(max_s / STEP_S)):
        _step(jaws, q_arm)
        v, w = p.getBaseVelocity(part_id, physicsClientId=cid)
        still = still + 1 if np.linalg.norm(v) < 1e-3 and np.linalg.norm(w) < 0.02 else 0
        if still >= 30:
            break


def stop(client_id: int, body_id: int) -> None:
    """Zero a body's velocity (after it was placed by hand)."""
    p.resetBaseVelocity(body_id, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], physicsClientId=client_id)
