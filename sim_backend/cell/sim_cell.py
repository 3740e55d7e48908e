"""SimCell: the whole simulated work cell in one PyBullet client (DIRECT mode).

A grey table, the PUMA 260 with gripper and hand camera (``robot_model``), the part to grasp
(``objects``), optionally an occluder lying on it and clutter around it, the light. Everything
moves kinematically: arm moves are solved by inverse kinematics and executed by setting the
joints (exact and fast); contact, wrench and gripping come from ``contact``. The arm reports
the pose it was commanded to (as VAL does); the pose it really reaches carries a random
repeatability error, and the camera and the ground truth see the real one.

World frame = the robot's base frame (VAL's X, Y, Z), z up, the table top at z = 0. Millimetres
and degrees in the interface; PyBullet is fed metres.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from drivers.core.errors import MotionRejectedError
from drivers.core.parts import APPROACH_HEIGHT_MM
from drivers.core.pose import Pose, rot_z, wrap_deg
from sim_backend.cell import contact, hand_camera, meshes, puma260, robot_model, textures
from sim_backend.cell.lighting import Light, resolve_light
from sim_backend.cell.objects import PARTS, PartSpec
from sim_backend.cell.pybullet_quiet import p
from sim_backend.cell.robot_model import FINGER_LINKS, TOOL_LENGTH_MM
from sim_backend.cell.scene_config import LightingConfig, SceneConfig, SimArmConfig
from sim_backend.cell.shadows import ShadowMap

logger = logging.getLogger(__name__)

REFERENCE_HEADING_DEG = 0.0  # tool x along world +x: the camera looks away from the robot
TABLE_MIN_MM = (-250.0, -500.0)
TABLE_MAX_MM = (850.0, 500.0)
TABLE_THICKNESS_MM = 40.0
GRIPPER_MASS_KG = 0.45
GRIPPER_COM_IN_TOOL_MM = (-15.0, 0.0, -80.0)
SENSOR_IN_TOOL_MM = (0.0, 0.0, -TOOL_LENGTH_MM + robot_model.SENSOR_LENGTH_MM)
# Seen from above at the pre-grasp pose (tool frame, mm): the fingers and palm, and the camera
# with its bracket. Clutter stays out of these (grown by its own size).
GRIPPER_FOOTPRINT_TOOL_MM = ((-25.0, 25.0, -42.0, 42.0), (-100.0, -20.0, -16.0, 16.0))
CLUTTER_MAX_DISTANCE_MM = 130.0
CLUTTER_COLORS = ((0.85, 0.2, 0.15), (0.2, 0.55, 0.25), (0.15, 0.3, 0.75), (1.0, 0.85, 0.1),
                  (0.95, 0.45, 0.1), (0.8, 0.65, 0.45))
OCCLUDER_COLOR = (0.32, 0.36, 0.48)
OCCLUDER_LENGTH_MM = 60.0
OCCLUDER_THICKNESS_MM = 2.0
DEFAULT_ARM = SimArmConfig()
# Where the inverse kinematics starts from: elbow up, wrist bent down over the table.
_IK_SEED_DEG = (0.0, 30.0, -180.0, -180.0, 30.0, 0.0)
# Labels of ``render_labels``.
LABEL_BACKGROUND, LABEL_PART, LABEL_ROBOT, LABEL_OCCLUDER, LABEL_CLUTTER = range(5)


def _tool_matrix(pose: Pose) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = pose.rotation()
    t[:3, 3] = pose.position_mm
    return t


def _translation(x_mm: float, y_mm: float, z_mm: float) -> np.ndarray:
    t = np.eye(4)
    t[:3, 3] = (x_mm, y_mm, z_mm)
    return t


TOOL_IN_FLANGE = _translation(0.0, 0.0, TOOL_LENGTH_MM)
FLANGE_IN_TOOL = np.linalg.inv(TOOL_IN_FLANGE)


def tool_down_rotation(heading_deg: float) -> np.ndarray:
    """Tool pointing straight down with its x axis at ``heading_deg`` in the world XY plane."""
    return rot_z(math.radians(heading_deg)) @ np.diag([1.0, -1.0, -1.0])


def _pose_to_pb(t_mm: np.ndarray) -> tuple[list[float], list[float]]:
    """PyBullet position (m) and quaternion of a 4x4 pose in mm."""
    return (t_mm[:3, 3] / 1000.0).tolist(), robot_model.quaternion(t_mm[:3, :3])


@dataclass
class _Item:
    """A body and its pose (4x4, mm) relative to the frame it is laid out in: the part's
    nominal grasp frame for the occluder and the clutter (identity for the part itself)."""

    body_id: int
    relative: np.ndarray
    label: int


class SimCell:
    """The simulated cell. Use as a context manager or call ``close()``.

    Args:
        scene: what the cell shows (part, table, light, occluder, clutter, camera noise).
        arm: the simulated arm's options (repeatability, contact stiffness, ...).
        seed: seeds the clutter layout, the occluder's side, the repeatability errors, the
            camera and the wrench noise; a given seed gives the same images (apart from the
            camera noise's own sequence, which is also seeded).
    """

    def __init__(self, scene: SceneConfig, arm: SimArmConfig = DEFAULT_ARM,
                 seed: int = 0) -> None:
        self.scene = scene
        self.arm_config = arm
        self.seed = seed
        layout, occluder, motion, noise, wrench = np.random.SeedSequence(seed).spawn(5)
        self._layout_rng = np.random.default_rng(layout)
        self._occluder_rng = np.random.default_rng(occluder)
        self._motion_rng = np.random.default_rng(motion)
        self._noise_rng = np.random.default_rng(noise)
        self._wrench_rng = np.random.default_rng(wrench)
        self.part: PartSpec = PARTS[scene.object.kind]
        self.light: Light = resolve_light(scene.lighting)
        self._textures = textures.TextureFiles()
        self._client = p.connect(p.DIRECT)
        self._closed = False
        try:
            self._build()
        except BaseException:
            self.close()
            raise

    # -- life cycle ---------------------------------------------------------------------------
    def close(self) -> None:
        """Disconnect the PyBullet client and delete the texture files. Safe to call twice."""
        if self._closed:
            return
        self._closed = True
        try:
            p.disconnect(physicsClientId=self._client)
        finally:
            self._textures.close()

    @property
    def is_open(self) -> bool:
        return not self._closed

    def __enter__(self) -> SimCell:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    # -- building -----------------------------------------------------------------------------
    def _build(self) -> None:
        cid = self._client
        palette = p.loadTexture(self._textures.write(textures.palette_texture()),
                                physicsClientId=cid)
        self._shading = p.loadTexture(self._textures.write(textures.part_shading()),
                                      physicsClientId=cid)
        self._table_id, self._table_rgba = self._build_table()
        self._robot = robot_model.build_robot(cid, palette)
        color = self.scene.object.color
        self._part = _Item(self._part_body(self.part, color), np.eye(4), LABEL_PART)
        self._occluder = self._build_occluder() if self.scene.occluder.enabled else None
        self._occluder_in_part = np.eye(4)
        self._clutter = [_Item(self._part_body(PARTS[kind], color), pose, LABEL_CLUTTER)
                         for kind, color, pose in self._clutter_layout(self.scene.clutter.count)]
        self._labels = {self._table_id: LABEL_BACKGROUND, self._robot.body_id: LABEL_ROBOT}
        for item in self._items():
            self._labels[item.body_id] = item.label
        self._shadow_map = ShadowMap(cid, self._table_id)
        self._held: np.ndarray | None = None
        self._finger_offset_mm = self.part.jaw_opening_mm / 2.0
        self._contacts: list[contact.Contact] | None = None
        obj = self.scene.object
        self._q_cmd = np.radians(_IK_SEED_DEG)
        self.place_object(obj.x_mm, obj.y_mm, obj.phi_deg)
        start = self.nominal_grasp_pose()
        self._q_cmd = self._solve(_tool_matrix(start))
        self._tool_cmd = _tool_matrix(start)
        self._tool_true = self._tool_cmd.copy()
        self._q_true = self._q_cmd.copy()
        self._robot.set_joints(self._q_true, self._finger_offset_mm)

    def _items(self) -> list[_Item]:
        """The part, the occluder (if any) and the clutter."""
        return [self._part, *([self._occluder] if self._occluder else []), *self._clutter]

    def _build_table(self) -> tuple[int, list[float]]:
        cid = self._client
        table = self.scene.table
        (x0, y0), (x1, y1) = TABLE_MIN_MM, TABLE_MAX_MM
        quad = meshes.grid_plane(TABLE_MIN_MM, TABLE_MAX_MM, 100.0, 1.0 / textures.TABLE_TILE_MM)
        textured = table.texture != "none"
        rgba = [1.0, 1.0, 1.0, 1.0] if textured else [*table.color, 1.0]
        visual = robot_model.visual_shape(quad, cid, rgba)
        half = [(x1 - x0) / 2000.0, (y1 - y0) / 2000.0, TABLE_THICKNESS_MM / 2000.0]
        collision = p.createCollisionShape(
            p.GEOM_BOX, halfExtents=half,
            collisionFramePosition=[(x0 + x1) / 2000.0, (y0 + y1) / 2000.0, -half[2]],
            physicsClientId=cid)
        body = p.createMultiBody(0.0, collision, visual, physicsClientId=cid)
        if textured:
            tex = p.loadTexture(self._textures.write(textures.table_texture(
                table.texture, table.color)), physicsClientId=cid)
            p.changeVisualShape(body, -1, textureUniqueId=tex, physicsClientId=cid)
        return body, rgba

    def _part_body(self, spec: PartSpec, color) -> int:
        cid = self._client
        visual = robot_model.visual_shape(spec.mesh, cid, [*color, 1.0])
        cylinders = spec.geometry.cylinders
        if cylinders:
            collision = p.createCollisionShapeArray(
                shapeTypes=[p.GEOM_CYLINDER] * len(cylinders),
                radii=[c.radius_mm / 1000.0 for c in cylinders],
                lengths=[c.length_mm / 1000.0 for c in cylinders],
                collisionFramePositions=[_pose_to_pb(c.pose_mm)[0] for c in cylinders],
                collisionFrameOrientations=[_pose_to_pb(c.pose_mm)[1] for c in cylinders],
                physicsClientId=cid)
        else:
            collision = p.createCollisionShape(
                p.GEOM_MESH, vertices=(spec.mesh.vertices_mm / 1000.0).tolist(),
                physicsClientId=cid)
        body = p.createMultiBody(0.0, collision, visual, physicsClientId=cid)
        # Convex hulls get a 1 mm collision margin by default: the jaws would stop early.
        p.changeDynamics(body, -1, collisionMargin=0.0, physicsClientId=cid)
        p.changeVisualShape(body, -1, textureUniqueId=self._shading, physicsClientId=cid)
        return body

    def _build_occluder(self) -> _Item:
        """A flat card lying on the part, covering ``coverage`` of its length along the part's
        x axis, from a side picked by the seed; as wide as the part's grasp, so the jaws pass."""
        cid = self._client
        coverage = self.scene.occluder.coverage
        extent = float(np.abs(self.part.mesh.vertices_mm[:, 0]).max())
        side = 1.0 if self._occluder_rng.random() < 0.5 else -1.0
        inner_edge = side * (extent - 2.0 * extent * coverage)
        centre_x = inner_edge + side * OCCLUDER_LENGTH_MM / 2.0
        half = np.array([OCCLUDER_LENGTH_MM / 2.0, self.part.grasp_width_mm / 2.0,
                         OCCLUDER_THICKNESS_MM / 2.0])
        visual = robot_model.visual_shape(meshes.box(half, meshes.BODY_U), cid,
                                          [*OCCLUDER_COLOR, 1.0])
        collision = p.createCollisionShape(p.GEOM_BOX, halfExtents=(half / 1000.0).tolist(),
                                           physicsClientId=cid)
        body = p.createMultiBody(0.0, collision, visual, physicsClientId=cid)
        z = self.part.height_mm + OCCLUDER_THICKNESS_MM / 2.0 + 0.2
        return _Item(body, _translation(centre_x, 0.0, z), LABEL_OCCLUDER)

    def _clutter_layout(self, count: int) -> list[tuple[str, tuple, np.ndarray]]:
        """Kinds, colours and poses (relative to the part's nominal grasp frame, z up) of
        ``count`` other parts: not touching the part or each other, clear of the gripper."""
        rng = self._layout_rng
        kinds = sorted(PARTS)
        placed: list[tuple[np.ndarray, float]] = []
        out = []
        for _ in range(count):
            kind = kinds[int(rng.integers(len(kinds)))]
            radius = PARTS[kind].footprint_radius_mm
            for _attempt in range(500):
                xy = rng.uniform(-CLUTTER_MAX_DISTANCE_MM, CLUTTER_MAX_DISTANCE_MM, 2)
                if self._clutter_fits(xy, radius, placed):
                    break
            else:
                raise RuntimeError(f"no room for {count} clutter parts")
            placed.append((xy, radius))
            color = CLUTTER_COLORS[int(rng.integers(len(CLUTTER_COLORS)))]
            pose = _translation(xy[0], xy[1], 0.0)
            pose[:3, :3] = rot_z(rng.uniform(0.0, 2.0 * math.pi))
            out.append((kind, color, pose))
        return out

    def _clutter_fits(self, xy: np.ndarray, radius: float,
                      placed: list[tuple[np.ndarray, float]]) -> bool:
        gap = 4.0
        if np.hypot(*xy) > CLUTTER_MAX_DISTANCE_MM:
            return False
        if np.hypot(*xy) < self.part.footprint_radius_mm + radius + gap:
            return False
        for x0, x1, y0, y1 in GRIPPER_FOOTPRINT_TOOL_MM:
            if (x0 - radius - gap < xy[0] < x1 + radius + gap
                    and y0 - radius - gap < xy[1] < y1 + radius + gap):
                return False
        return all(np.hypot(*(xy - other)) >= radius + r + gap for other, r in placed)

    # -- the part -------------------------------------------------------------------------------
    @property
    def object_kind(self) -> str:
        return self.part.kind

    @property
    def kappa(self) -> int:
        return self.part.kappa

    @property
    def approach_height_mm(self) -> float:
        """Fingertips above the part's top at the pre-grasp (nominal) pose."""
        return APPROACH_HEIGHT_MM

    @property
    def grasp_depth_mm(self) -> float:
        """How far to descend along the approach axis from the nominal pose to grip the part."""
        return self.part.grasp_depth_mm

    @property
    def holding(self) -> bool:
        """Whether the jaws hold the part."""
        return self._held is not None

    def place_object(self, x_mm: float, y_mm: float, phi_deg: float) -> None:
        """Put the part on the table at (x, y) turned by phi about the vertical (releasing it if
        held); the occluder and clutter keep their places around it."""
        for name, v in (("x_mm", x_mm), ("y_mm", y_mm), ("phi_deg", phi_deg)):
            if not math.isfinite(v):
                raise ValueError(f"{name} must be a finite number, got {v!r}")
        pose = _translation(x_mm, y_mm, 0.0)
        pose[:3, :3] = rot_z(math.radians(phi_deg))
        nominal = self._nominal_matrix(pose)
        try:
            self._solve(nominal)
        except MotionRejectedError as exc:
            raise ValueError(f"the pre-grasp pose over a part at ({x_mm:g}, {y_mm:g}) mm is "
                             f"out of the arm's reach: {exc.reason}") from exc
        self._held = None
        # Occluder and clutter are laid out in the nominal grasp frame (x along the tool's
        # heading), so the gripper's footprint is known in it.
        frame = nominal.copy()
        frame[2, 3] = 0.0
        frame[:3, :3] = rot_z(math.radians(self._nominal_heading_deg(pose)))
        self._occluder_in_part = np.linalg.inv(pose) @ frame
        self._set_part_pose(pose)
        for item in self._clutter:
            self._place_body(item.body_id, frame @ item.relative)

    def object_pose(self) -> tuple[float, float, float]:
        """(x_mm, y_mm, phi_deg) of the part on the table (phi in (-180, 180])."""
        t = self._part_pose
        return (float(t[0, 3]), float(t[1, 3]),
                wrap_deg(math.degrees(math.atan2(t[1, 0], t[0, 0]))))

    def _set_part_pose(self, pose: np.ndarray) -> None:
        """Move the part (and the occluder lying on it)."""
        self._part_pose = pose
        self._place_body(self._part.body_id, pose)
        if self._occluder is not None:
            self._place_body(self._occluder.body_id,
                             pose @ self._occluder_in_part @ self._occluder.relative)
        self._contacts = None

    def _place_body(self, body: int, pose_mm: np.ndarray) -> None:
        pos, orn = _pose_to_pb(pose_mm)
        p.resetBasePositionAndOrientation(body, pos, orn, physicsClientId=self._client)

    @staticmethod
    def _heading_of(pose: np.ndarray) -> float:
        return math.degrees(math.atan2(pose[1, 0], pose[0, 0]))

    def _nominal_heading_deg(self, part_pose: np.ndarray) -> float:
        period = 360.0 / self.part.kappa
        phi = self._heading_of(part_pose)
        return REFERENCE_HEADING_DEG + wrap_deg(phi - REFERENCE_HEADING_DEG, period)

    def _nominal_matrix(self, part_pose: np.ndarray) -> np.ndarray:
        t = np.eye(4)
        t[:3, :3] = tool_down_rotation(self._nominal_heading_deg(part_pose))
        t[:3, 3] = part_pose[:3, 3] + [0.0, 0.0, self.part.height_mm + APPROACH_HEIGHT_MM]
        return t

    def nominal_grasp_pose(self) -> Pose:
        """The pre-grasp pose for the part where it lies: tool pointing down, the TCP (between
        the fingertips) above the grasp point at the approach height, the jaws square to the
        part's faces (of the 360/kappa equivalent turns, the one nearest the reference)."""
        t = self._nominal_matrix(self._part_pose)
        return Pose.from_matrix(t[:3, 3], t[:3, :3])

    def ground_truth_error(self) -> tuple[float, float, float]:
        """(ex_mm, ey_mm, ephi_deg): where the gripper really is relative to the nominal pose,
        in the nominal tool frame, ephi wrapped into (-180/kappa, 180/kappa]."""
        step = self.nominal_grasp_pose().tool_step_to(self.true_tool_pose())
        return step.dx_mm, step.dy_mm, wrap_deg(step.dphi_deg, 360.0 / self.part.kappa)

    # -- the arm ------------------------------------------------------------------------------
    def arm_pose(self) -> Pose:
        """The tool pose the arm reports (the one it was commanded to)."""
        return Pose.from_matrix(self._tool_cmd[:3, 3], self._tool_cmd[:3, :3])

    def true_tool_pose(self) -> Pose:
        """The tool pose the arm really reached (commanded pose plus repeatability error)."""
        return Pose.from_matrix(self._tool_true[:3, 3], self._tool_true[:3, :3])

    def joint_angles_deg(self) -> np.ndarray:
        return np.degrees(self._q_true)

    def _solve(self, tool: np.ndarray) -> np.ndarray:
        return puma260.inverse_kinematics(tool @ FLANGE_IN_TOOL, self._q_cmd)

    def _repeatability_error(self) -> np.ndarray:
        """A random rigid displacement within the configured repeatability (4x4, mm)."""
        rng, cfg = self._motion_rng, self.arm_config
        e = np.eye(4)
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        angle = math.radians(cfg.repeatability_deg) * rng.uniform(0.0, 1.0)
        k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]],
                      [-axis[1], axis[0], 0.0]])
        e[:3, :3] = np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)
        direction = rng.normal(size=3)
        e[:3, 3] = direction / np.linalg.norm(direction) * cfg.repeatability_mm * rng.uniform()
        return e

    def move_arm(self, target: Pose) -> Pose:
        """Move the tool to ``target`` (atomic); returns the reported pose reached.

        Raises MotionRejectedError, with nothing moved, when the target is out of reach or
        outside the joint limits, or would push the gripper (or a held part) more than
        ``max_penetration_mm`` into the table or a part.
        """
        if not target.is_finite():
            raise MotionRejectedError(f"target pose is not finite: {target}")
        tool_cmd = _tool_matrix(target)
        try:
            q_cmd = self._solve(tool_cmd)
        except MotionRejectedError as exc:
            logger.warning("motion rejected: %s", exc.reason)
            raise
        tool_true = tool_cmd @ self._repeatability_error()
        try:
            q_true = puma260.inverse_kinematics(tool_true @ FLANGE_IN_TOOL, q_cmd)
        except MotionRejectedError:  # at the very edge of reach: no error this time
            tool_true, q_true = tool_cmd, q_cmd
        previous = (self._q_true, self._tool_true)
        self._set_arm(q_true, tool_true)
        deepest = max(self._touching(), key=lambda c: c.depth_mm, default=None)
        if deepest is not None and deepest.depth_mm > self.arm_config.max_penetration_mm:
            self._set_arm(*previous)
            what = {self._table_id: "the table"}.get(deepest.body_b, "a part")
            reason = (f"collision: the move would push the gripper {deepest.depth_mm:.1f} mm "
                      f"into {what} (limit {self.arm_config.max_penetration_mm:g} mm)")
            logger.warning("motion rejected: %s", reason)
            raise MotionRejectedError(reason)
        self._q_cmd, self._tool_cmd = q_cmd, tool_cmd
        return self.arm_pose()

    def _set_arm(self, q_true: np.ndarray, tool_true: np.ndarray) -> None:
        self._q_true, self._tool_true = q_true, tool_true
        self._robot.set_joints(q_true, self._finger_offset_mm)
        if self._held is not None:
            self._set_part_pose(tool_true @ self._held)
        self._contacts = None

    # -- the gripper --------------------------------------------------------------------------
    def finger_width_mm(self) -> float:
        return 2.0 * self._finger_offset_mm

    def open_gripper(self) -> float:
        """Open the jaws fully, letting go of a held part (it comes to rest on the table)."""
        if self._held is not None:
            self._held = None
            x, y, phi = self.object_pose()
            rest = _translation(x, y, 0.0)
            rest[:3, :3] = rot_z(math.radians(phi))
            self._set_part_pose(rest)
        self._set_fingers(self.part.jaw_opening_mm / 2.0)
        return self.finger_width_mm()

    def close_gripper(self) -> float:
        """Close the jaws until they grip the part or meet; returns the finger width (mm)."""
        if self._held is not None:
            return self.finger_width_mm()
        jaw_axis = self._tool_true[:3, 1]
        result = contact.close_on(
            self._client, self._robot.body_id, FINGER_LINKS, self._part.body_id, jaw_axis,
            self._finger_offset_mm, self._set_fingers, self._push_part)
        self._set_fingers(result.offset_mm)
        if result.gripping:
            self._held = np.linalg.inv(self._tool_true) @ self._part_pose
        return self.finger_width_mm()

    def _set_fingers(self, offset_mm: float) -> None:
        self._finger_offset_mm = offset_mm
        self._robot.set_fingers(offset_mm)
        self._contacts = None

    def _push_part(self, delta_mm: np.ndarray) -> None:
        pose = self._part_pose.copy()
        pose[:2, 3] += delta_mm[:2]
        self._set_part_pose(pose)

    # -- contact and the wrist sensor -----------------------------------------------------------
    def _environment(self, exclude: int | None = None) -> list[int]:
        bodies = [self._table_id, *(item.body_id for item in self._items())]
        return [b for b in bodies if b != exclude]

    def _touching(self) -> list[contact.Contact]:
        if self._contacts is None:
            robot = self._robot.body_id
            part = self._part.body_id
            if self._held is None:
                found = contact.contacts(self._client, robot, self._environment())
            else:
                skip = frozenset((link, part) for link in FINGER_LINKS)
                found = contact.contacts(self._client, robot, self._environment(), skip=skip)
                found += contact.contacts(self._client, part, self._environment(exclude=part))
            self._contacts = found
        return self._contacts

    def wrench(self, noisy: bool = True) -> np.ndarray:
        """(Fx, Fy, Fz [N], Tx, Ty, Tz [N*m]): what the wrist sensor feels, in the tool frame
        (z = approach axis), about its measuring point; unbiased (gravity included).

        Forces are those the environment exerts on the tool: pressing the gripper down onto
        the table gives Fz < 0 (the table pushes back against the approach direction).
        """
        t = self._tool_true
        loads = [(GRIPPER_MASS_KG, (t @ [*GRIPPER_COM_IN_TOOL_MM, 1.0])[:3])]
        if self._held is not None:
            loads.append((self.part.mass_g / 1000.0,
                          self._part_pose[:3, 3] + [0.0, 0.0, self.part.height_mm / 2.0]))
        sensor = (t @ [*SENSOR_IN_TOOL_MM, 1.0])[:3]
        w = contact.wrench_in_tool(self._touching(), self.arm_config.contact_stiffness_n_per_mm,
                                   sensor, t[:3, :3], loads)
        if noisy and self.arm_config.wrench_noise_n > 0:
            sigma = self.arm_config.wrench_noise_n
            w = w + self._wrench_rng.normal(0.0, 1.0, 6) * np.array([sigma] * 3 + [sigma / 10] * 3)
        return w

    # -- light and camera -----------------------------------------------------------------------
    def set_lighting(self, lighting: LightingConfig | str) -> Light:
        """Change the light: a LightingConfig, or a preset name (good, poor, dim, side)."""
        config = LightingConfig(preset=lighting) if isinstance(lighting, str) else lighting
        self.light = resolve_light(config)
        return self.light

    def camera_to_world(self) -> np.ndarray:
        """4x4 pose (mm) of the hand camera (x right, y down, z forward)."""
        return self._tool_true @ hand_camera.camera_in_tool()

    def _render_raw(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        light = self.light
        _, _, rgba, depth, seg = p.getCameraImage(
            hand_camera.WIDTH_PX, hand_camera.HEIGHT_PX,
            hand_camera.view_matrix(self.camera_to_world()), hand_camera.projection_matrix(),
            lightDirection=list(light.direction), lightColor=list(light.color),
            lightAmbientCoeff=light.ambient, lightDiffuseCoeff=light.diffuse,
            lightSpecularCoeff=light.specular, shadow=0, renderer=p.ER_TINY_RENDERER,
            physicsClientId=self._client)
        shape = (hand_camera.HEIGHT_PX, hand_camera.WIDTH_PX)
        rgb = np.reshape(np.asarray(rgba, dtype=np.uint8), (*shape, 4))[:, :, :3]
        return (rgb, np.reshape(np.asarray(depth, dtype=np.float32), shape),
                np.reshape(np.asarray(seg, dtype=np.int32), shape))

    def render(self, noisy: bool = True) -> np.ndarray:
        """What the hand camera sees: HxWx3 uint8 RGB (192x144), with cast shadows and, when
        ``noisy``, the configured camera noise."""
        rgb, depth, seg = self._render_raw()
        if self.light.casts_shadows:
            cam = self.camera_to_world()
            centre = self._shadow_centre(cam)
            rgb = self._shadow_map.apply(rgb, depth, seg, cam, self.light, centre,
                                         self._table_rgba)
        std = self.scene.camera.noise_std
        if noisy and std > 0:
            noise = self._noise_rng.standard_normal(rgb.shape, dtype=np.float32) * std
            rgb = np.clip(rgb + noise + 0.5, 0, 255).astype(np.uint8)
        return np.ascontiguousarray(rgb)

    @staticmethod
    def _shadow_centre(cam: np.ndarray) -> np.ndarray:
        """Where the optical axis meets the table (or the point below the camera)."""
        origin, axis = cam[:3, 3], cam[:3, 2]
        if axis[2] < -1e-3:
            return origin + axis * (-origin[2] / axis[2])
        return np.array([origin[0], origin[1], 0.0])

    def render_labels(self) -> np.ndarray:
        """HxW int labels of what each camera pixel shows: LABEL_BACKGROUND (table, nothing),
        LABEL_PART, LABEL_ROBOT, LABEL_OCCLUDER, LABEL_CLUTTER."""
        _, _, seg = self._render_raw()
        out = np.full(seg.shape, LABEL_BACKGROUND, dtype=np.int32)
        for body, label in self._labels.items():
            out[seg == body] = label
        return out
