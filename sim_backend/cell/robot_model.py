"""The PUMA 260 with its gripper and hand camera as one PyBullet multibody, built from the DH table.

PyBullet link i-1 carries joint i; its frame is DH frame i-1 turned by q_i about its z axis, so
the fixed part of DH row i (Tz(d) Tx(a) Rx(alpha)) is the offset of the next link. Link 6 is the
gripper (fixed to the flange: F/T sensor, palm, camera bracket and housing), links 7 and 8 the
fingers (prismatic, along the tool's +y and -y; the joint value is the distance of the finger's
inner face from the tool axis). Visual shapes are procedural meshes coloured from one palette
texture, so the robot casts shadows like everything else. Only the gripper links collide.

Tool frame: the flange frame moved TOOL_LENGTH_MM along its z axis: the TCP lies between the
fingertips, z is the approach axis.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim_backend.cell import hand_camera, meshes
from sim_backend.cell.meshes import Mesh
from sim_backend.cell.puma260 import DH_ROWS
from sim_backend.cell.pybullet_quiet import p
from sim_backend.cell.textures import palette_u

TOOL_LENGTH_MM = 120.0  # flange to the TCP (fingertips)
SENSOR_LENGTH_MM = 28.0
SENSOR_RADIUS_MM = 22.0
PALM_HALF_MM = (22.0, 38.0, 17.0)
FINGER_LENGTH_MM = 58.0
FINGER_THICKNESS_MM = 8.0  # along the jaw axis (tool y)
FINGER_DEPTH_MM = 16.0  # along tool x
HOUSING_HALF_MM = (12.0, 12.0, 16.0)
# Where the palm's underside (the fingers' root) is, in the tool frame.
PALM_BOTTOM_IN_TOOL_MM = -FINGER_LENGTH_MM

ARM_JOINTS = (0, 1, 2, 3, 4, 5)
GRIPPER_LINK = 6
FINGER_LINKS = (7, 8)  # +y finger, -y finger
_LINK_MASS_KG = 0.5  # never simulated dynamically; PyBullet wants a mass for moving links


@dataclass(frozen=True)
class RobotBody:
    """The multibody's id in its PyBullet client."""

    body_id: int
    client_id: int

    def set_joints(self, q_rad, finger_offset_mm: float) -> None:
        """Put the arm at ``q_rad``, each finger's inner face ``finger_offset_mm`` off the axis."""
        for joint, q in zip(ARM_JOINTS, q_rad, strict=True):
            p.resetJointState(self.body_id, joint, float(q), physicsClientId=self.client_id)
        self.set_fingers(finger_offset_mm)

    def set_fingers(self, offset_mm: float) -> None:
        """Put each finger's inner face ``offset_mm`` off the tool axis."""
        for joint in FINGER_LINKS:
            p.resetJointState(self.body_id, joint, offset_mm / 1000.0,
                              physicsClientId=self.client_id)


def quaternion(rotation: np.ndarray) -> list[float]:
    """Quaternion (x, y, z, w) of a rotation matrix."""
    m = rotation
    w = np.sqrt(max(0.0, 1.0 + m[0, 0] + m[1, 1] + m[2, 2])) / 2.0
    x = np.sqrt(max(0.0, 1.0 + m[0, 0] - m[1, 1] - m[2, 2])) / 2.0
    y = np.sqrt(max(0.0, 1.0 - m[0, 0] + m[1, 1] - m[2, 2])) / 2.0
    z = np.sqrt(max(0.0, 1.0 - m[0, 0] - m[1, 1] + m[2, 2])) / 2.0
    x = np.copysign(x, m[2, 1] - m[1, 2])
    y = np.copysign(y, m[0, 2] - m[2, 0])
    z = np.copysign(z, m[1, 0] - m[0, 1])
    return [float(x), float(y), float(z), float(w)]


def _rot_x(angle_rad: float) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _link_visuals() -> list[Mesh]:
    """Meshes (mm, link frame) of the base and links 0..8; see the module docstring."""
    paint, joint = palette_u("paint"), palette_u("joint")
    cyl, box, placed = meshes.cylinder, meshes.box, meshes.placed
    about_y = _rot_x(np.pi / 2)  # cylinder axis z -> -y
    base = Mesh.concat([placed(cyl(75.0, 20.0, joint), None, (0, 0, 10)),
                        placed(cyl(62.0, 220.0, paint), None, (0, 0, 130))])
    link1 = Mesh.concat([placed(cyl(55.0, 60.0, paint), None, (0, 0, 270)),
                         placed(cyl(48.0, 110.0, joint), about_y, (0, 10, 330.2))])
    a2, d2 = DH_ROWS[1][0], DH_ROWS[1][2]
    link2 = Mesh.concat([placed(box((a2 / 2 + 20, 26, 18), paint), None, (a2 / 2, 0, d2)),
                         placed(cyl(42.0, 40.0, paint), None, (0, 0, d2)),
                         placed(cyl(34.0, 40.0, paint), None, (a2, 0, d2))])
    d3 = DH_ROWS[2][2]
    link3 = Mesh.concat([placed(cyl(32.0, 50.0, joint), None, (0, 0, d3 / 2)),
                         placed(box((26, 30, 22), paint), None, (0, 20, d3))])
    d4 = DH_ROWS[3][2]
    link4 = placed(cyl(27.0, d4 - 60.0, paint), None, (0, 0, d4 / 2 - 10))
    link5 = placed(cyl(24.0, 56.0, joint), None, (0, 0, 0))
    d6 = DH_ROWS[5][2]
    link6 = placed(cyl(19.0, d6 - 20.0, joint), None, (0, 0, d6 / 2 + 10))
    return [base, link1, link2, link3, link4, link5, link6, _gripper_visual(), *_finger_visuals()]


def _tool_to_flange(point_tool_mm) -> np.ndarray:
    return np.asarray(point_tool_mm, dtype=float) + [0.0, 0.0, TOOL_LENGTH_MM]


def _gripper_visual() -> Mesh:
    """Sensor, palm, camera bracket and housing, in the flange frame (mm)."""
    metal, camera = palette_u("metal"), palette_u("camera")
    sensor = meshes.placed(meshes.cylinder(SENSOR_RADIUS_MM, SENSOR_LENGTH_MM, palette_u("joint")),
                           None, (0, 0, SENSOR_LENGTH_MM / 2))
    palm = meshes.placed(meshes.box(PALM_HALF_MM, metal), None, _palm_centre_flange())
    housing_centre, housing_rotation = housing_centre_and_rotation_tool()
    housing = meshes.placed(meshes.box(HOUSING_HALF_MM, camera), housing_rotation,
                            _tool_to_flange(housing_centre))
    bracket_x0, bracket_x1 = -PALM_HALF_MM[0], housing_centre[0]
    bracket_z = housing_centre[2] - HOUSING_HALF_MM[2]
    bracket = meshes.placed(meshes.box(((bracket_x0 - bracket_x1) / 2, 7.0, 5.0), metal), None,
                            _tool_to_flange(((bracket_x0 + bracket_x1) / 2, 0.0, bracket_z)))
    return Mesh.concat([sensor, palm, housing, bracket])


def _palm_centre_flange() -> np.ndarray:
    return _tool_to_flange((0.0, 0.0, PALM_BOTTOM_IN_TOOL_MM - PALM_HALF_MM[2]))


def _finger_half_mm() -> tuple[float, float, float]:
    return (FINGER_DEPTH_MM / 2, FINGER_THICKNESS_MM / 2, FINGER_LENGTH_MM / 2)


def _finger_centre(sign: float) -> tuple[float, float, float]:
    """Centre of a finger's box in its link frame (root of the finger, inner face at y = 0)."""
    return (0.0, sign * FINGER_THICKNESS_MM / 2, FINGER_LENGTH_MM / 2)


def _finger_visuals() -> list[Mesh]:
    u = palette_u("finger")
    return [meshes.placed(meshes.box(_finger_half_mm(), u), None, _finger_centre(sign))
            for sign in (1.0, -1.0)]


def housing_centre_and_rotation_tool() -> tuple[np.ndarray, np.ndarray]:
    """Centre (mm) and rotation of the camera housing box in the tool frame: behind the lens,
    along the optical axis."""
    cam = hand_camera.camera_in_tool()
    return cam[:3, 3] - (HOUSING_HALF_MM[2] + 1.0) * cam[:3, 2], cam[:3, :3]


def visual_shape(mesh: Mesh, client_id: int, rgba=(1.0, 1.0, 1.0, 1.0)) -> int:
    """A PyBullet visual shape of ``mesh`` (mm) tinted ``rgba``."""
    return p.createVisualShape(
        p.GEOM_MESH, vertices=(mesh.vertices_mm / 1000.0).tolist(),
        indices=mesh.triangles.reshape(-1).tolist(), uvs=mesh.uvs.tolist(),
        normals=mesh.normals.tolist(), rgbaColor=list(rgba), physicsClientId=client_id)


def _gripper_collision(client_id: int) -> int:
    centre, rot = housing_centre_and_rotation_tool()
    half_m = [[v / 1000.0 for v in PALM_HALF_MM], [v / 1000.0 for v in HOUSING_HALF_MM]]
    positions = [(_palm_centre_flange() / 1000.0).tolist(),
                 (_tool_to_flange(centre) / 1000.0).tolist()]
    return p.createCollisionShapeArray(
        shapeTypes=[p.GEOM_BOX, p.GEOM_BOX], halfExtents=half_m,
        collisionFramePositions=positions,
        collisionFrameOrientations=[[0.0, 0.0, 0.0, 1.0], quaternion(rot)],
        physicsClientId=client_id)


def build_robot(client_id: int, palette_texture_id: int) -> RobotBody:
    """Create the arm, gripper and camera housing in ``client_id``; joints all at zero."""
    visuals = [visual_shape(m, client_id) for m in _link_visuals()]
    finger_col = p.createCollisionShape(
        p.GEOM_BOX, halfExtents=[v / 1000.0 for v in _finger_half_mm()],
        collisionFramePosition=[0.0, FINGER_THICKNESS_MM / 2000.0, FINGER_LENGTH_MM / 2000.0],
        physicsClientId=client_id)
    finger_col_neg = p.createCollisionShape(
        p.GEOM_BOX, halfExtents=[v / 1000.0 for v in _finger_half_mm()],
        collisionFramePosition=[0.0, -FINGER_THICKNESS_MM / 2000.0, FINGER_LENGTH_MM / 2000.0],
        physicsClientId=client_id)
    positions, orientations = [[0.0, 0.0, 0.0]], [[0.0, 0.0, 0.0, 1.0]]
    for a, alpha, d in DH_ROWS[:5]:
        positions.append([a / 1000.0, 0.0, d / 1000.0])
        orientations.append(quaternion(_rot_x(alpha)))
    positions.append([0.0, 0.0, DH_ROWS[5][2] / 1000.0])  # gripper on the flange
    orientations.append([0.0, 0.0, 0.0, 1.0])
    finger_root = (TOOL_LENGTH_MM + PALM_BOTTOM_IN_TOOL_MM) / 1000.0
    positions += [[0.0, 0.0, finger_root]] * 2
    orientations += [[0.0, 0.0, 0.0, 1.0]] * 2
    n = len(positions)
    body = p.createMultiBody(
        baseMass=0.0, baseCollisionShapeIndex=-1, baseVisualShapeIndex=visuals[0],
        linkMasses=[_LINK_MASS_KG] * n,
        linkCollisionShapeIndices=[-1] * 6 + [_gripper_collision(client_id), finger_col,
                                             finger_col_neg],
        linkVisualShapeIndices=visuals[1:],
        linkPositions=positions, linkOrientations=orientations,
        linkInertialFramePositions=[[0.0, 0.0, 0.0]] * n,
        linkInertialFrameOrientations=[[0.0, 0.0, 0.0, 1.0]] * n,
        linkParentIndices=[0, 1, 2, 3, 4, 5, 6, 7, 7],
        linkJointTypes=[p.JOINT_REVOLUTE] * 6 + [p.JOINT_FIXED, p.JOINT_PRISMATIC,
                                                 p.JOINT_PRISMATIC],
        linkJointAxis=[[0.0, 0.0, 1.0]] * 7 + [[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]],
        physicsClientId=client_id)
    for link in range(-1, n):
        p.changeVisualShape(body, link, textureUniqueId=palette_texture_id,
                            physicsClientId=client_id)
    return RobotBody(body, client_id)

