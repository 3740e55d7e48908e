"""SimCell: the whole simulated work cell in one PyBullet client (DIRECT mode).

A grey table, the PUMA 260 with gripper and hand camera (``robot_model``), the part to grasp
(``objects``), optionally an occluder lying on it and clutter around it, the light. The arm
moves kinematically: arm moves are solved by inverse kinematics and executed by setting the
joints (exact and fast); a move into the table or a part stalls against it; the wrench comes
from the contact model (``contact``). The part is a dynamic body, stepped only while the jaws
close, the part is lifted or let go (``grasp_physics``). The arm reports
the pose it was commanded to (as VAL does); the pose it really reaches carries a random
repeatability error, and the camera and the ground truth see the real one.

World frame = the robot's base frame (VAL's X, Y, Z), z up, the table top at z = 0. Millimetres
and degrees in the interface; PyBullet is fed metres.
"""

from __future__ import annotations

import logging
import math
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drivers.core.errors import MotionRejectedError
from drivers.core.parts import APPROACH_HEIGHT_MM, Catalogue
from drivers.core.parts import PARTS as CATALOGUE
from drivers.core.pose import Pose, rot_y, rot_z, wrap_deg
from sim_backend.cell import (
    contact,
    grasp_physics,
    hand_camera,
    meshes,
    optics,
    puma260,
    robot_model,
    textures,
)
from sim_backend.cell.lighting import Light, resolve_light
from sim_backend.cell.objects import PARTS, PartSpec, spec_for
from sim_backend.cell.pybullet_quiet import p
from sim_backend.cell.robot_model import FINGER_LINKS, TOOL_LENGTH_MM
from sim_backend.cell.scene_config import (
    LightingConfig,
    MountConfig,
    SceneConfig,
    SimArmConfig,
)
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
OCCLUDER_LENGTH_MM = 120.0
OCCLUDER_THICKNESS_MM = 2.0
OCCLUDER_MIN_OVERLAP_MM = 2.0  # how far the card reaches onto the part at least
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


def _card_slope(u_mm: np.ndarray, z_mm: np.ndarray, length_mm: float) -> float:
    """The slope (rad) of a straight card of ``length_mm`` whose inner end lies at u = 0 and
    outer end on the table (z = 0), resting on the part's points (u, z) beneath it: the
    least slope, to a quarter degree, at which its underside clears every one of them."""
    for step in range(1, 321):  # 0.25 deg steps up to 80 deg
        slope = math.radians(0.25 * step)
        out = length_mm * math.cos(slope)
        below = (u_mm >= 0.0) & (u_mm <= out)
        height = length_mm * math.sin(slope) - u_mm[below] * math.tan(slope)
        if np.all(height >= z_mm[below] - 1e-6):
            return slope
    raise ValueError("the card is too short to lie over this part")


def _translation(x_mm: float, y_mm: float, z_mm: float) -> np.ndarray:
    t = np.eye(4)
    t[:3, 3] = (x_mm, y_mm, z_mm)
    return t


TOOL_IN_FLANGE = _translation(0.0, 0.0, TOOL_LENGTH_MM)
FLANGE_IN_TOOL = np.linalg.inv(TOOL_IN_FLANGE)


def tool_down_rotation(heading_deg: float) -> np.ndarray:
    """Tool pointing straight down with its x axis at ``heading_deg`` in the world XY plane."""
    return rot_z(math.radians(heading_deg)) @ np.diag([1.0, -1.0, -1.0])


def _interpolate(a: np.ndarray, b: np.ndarray, s: float) -> np.ndarray:
    """The 4x4 pose (mm) a fraction ``s`` of the way from ``a`` to ``b`` (straight line, the
    rotation about its fixed axis)."""
    rel = a[:3, :3].T @ b[:3, :3]
    angle = math.acos(float(np.clip((np.trace(rel) - 1.0) / 2.0, -1.0, 1.0)))
    out = np.eye(4)
    out[:3, 3] = a[:3, 3] + s * (b[:3, 3] - a[:3, 3])
    if angle < 1e-9:
        out[:3, :3] = a[:3, :3]
        return out
    axis = np.array([rel[2, 1] - rel[1, 2], rel[0, 2] - rel[2, 0], rel[1, 0] - rel[0, 1]])
    axis /= max(np.linalg.norm(axis), 1e-12)
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    t = s * angle
    out[:3, :3] = a[:3, :3] @ (np.eye(3) + math.sin(t) * k + (1.0 - math.cos(t)) * (k @ k))
    return out


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
        parts: the parts catalogue ``scene.object.kind`` is looked up in (the cell config's,
            with its declared parts; default: the built-in parts). Clutter is drawn from the
            built-in parts.

    Raises:
        ConfigError: an unknown part, or a declared part's mesh file that cannot be used
            (one line naming the key, ``sim_backend.cell.mesh_files``).
    """

    def __init__(self, scene: SceneConfig, arm: SimArmConfig = DEFAULT_ARM,
                 seed: int = 0, parts: Catalogue | None = None) -> None:
        self.scene = scene
        self.arm_config = arm
        self.seed = seed
        layout, occluder, motion, noise, wrench = np.random.SeedSequence(seed).spawn(5)
        self._layout_rng = np.random.default_rng(layout)
        self._occluder_rng = np.random.default_rng(occluder)
        self._motion_rng = np.random.default_rng(motion)
        self._noise_rng = np.random.default_rng(noise)
        self._wrench_rng = np.random.default_rng(wrench)
        self.part: PartSpec = spec_for((parts or CATALOGUE).part(scene.object.kind))
        self.light: Light = resolve_light(scene.lighting)
        self.camera_model = optics.resolve_camera(scene.camera)
        self._optics = (None if self.camera_model.ideal
                        else optics.CameraPipeline(self.camera_model, self._noise_rng))
        self._mount = scene.camera.mount
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
        self._jaws = grasp_physics.setup(cid, self._robot.body_id, self._table_id,
                                         self.part.friction)
        color = self.scene.object.color or self.part.color
        self._part = _Item(self._part_body(self.part, color), np.eye(4), LABEL_PART)
        # The part is a dynamic body: it moves by itself only while a grasp steps the physics.
        grasp_physics.make_dynamic(cid, self._part.body_id, self.part.mass_g / 1000.0,
                                   self.part.friction)
        self._occluder = self._build_occluder() if self.scene.occluder.enabled else None
        if self._occluder is not None:  # the card lies on the part: it goes where the part goes
            for link in (-1, *FINGER_LINKS):
                body = self._robot.body_id if link >= 0 else self._part.body_id
                p.setCollisionFilterPair(body, self._occluder.body_id, link, -1, 0,
                                         physicsClientId=cid)
        self._occluder_in_part = np.eye(4)
        self._clutter = [_Item(self._part_body(PARTS[kind], color), pose, LABEL_CLUTTER)
                         for kind, color, pose in self._clutter_layout(self.scene.clutter.count)]
        self._labels = {self._table_id: LABEL_BACKGROUND, self._robot.body_id: LABEL_ROBOT}
        for item in self._items():
            self._labels[item.body_id] = item.label
        self._shadow_map = ShadowMap(cid, self._table_id)
        self._shaded: tuple[bytes, np.ndarray] | None = None  # the last scene's samples
        self._held: np.ndarray | None = None  # the part in the tool frame while held
        self._gripping = False  # jaws closed on the part, its hold not yet tested by a lift
        self._motion_dir: np.ndarray | None = None  # of the tool's last move (contact drag)
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
        if spec.geometry.hulls_obj is not None:
            collision = self._hulls_shape(spec.geometry.hulls_obj)
        elif cylinders:
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

    def _hulls_shape(self, hulls_obj: str) -> int:
        """A compound collision shape of the convex pieces in ``hulls_obj`` (OBJ text, mm):
        PyBullet makes one convex hull of each object of an OBJ file."""
        with tempfile.TemporaryDirectory(prefix="finepos-hulls-") as tmp:
            path = Path(tmp) / "hulls.obj"
            path.write_text(hulls_obj, encoding="utf-8")
            return p.createCollisionShape(p.GEOM_MESH, fileName=str(path),
                                          meshScale=[1e-3] * 3, physicsClientId=self._client)

    def _build_occluder(self) -> _Item:
        """A flat card lying over one end of the part (the seed picks which; a screw: its head
        or its tip), as wide as the part's grasp, so the jaws pass. A card this long does not
        lie flat on a part this small: it rests on the part's edge and on the table beyond,
        sloping down from the part. Its inner end lies over the part where, as the hand camera
        sees the part from the pre-grasp pose, the card hides ``coverage`` of its length in
        view. The camera looks from an angle, so over the end nearer the camera the card also
        hides that end's side faces: it hides more there (it must reach onto the part to lie
        on it) and ``coverage`` is the least it hides."""
        cid = self._client
        coverage = self.scene.occluder.coverage
        half_t = OCCLUDER_THICKNESS_MM / 2.0
        x = self._seen_along_x(self.part.height_mm + OCCLUDER_THICKNESS_MM)
        side = 1.0 if self._occluder_rng.random() < 0.5 else -1.0
        end = float(x.max() if side > 0.0 else x.min())
        vertices = self.part.mesh.vertices_mm
        reach = float(vertices[:, 0].max() if side > 0.0 else -vertices[:, 0].min())
        # u: distance outwards from the card's inner end, along the part's x axis
        inner = end - side * coverage * float(x.max() - x.min())
        inner = side * min(side * inner, reach - OCCLUDER_MIN_OVERLAP_MM)
        slope = _card_slope(side * (vertices[:, 0] - inner), vertices[:, 2], OCCLUDER_LENGTH_MM)
        length = OCCLUDER_LENGTH_MM / 2.0
        pose = _translation(inner + side * (length * math.cos(slope) + half_t * math.sin(slope)),
                            0.0, length * math.sin(slope) + half_t * math.cos(slope) + 0.2)
        pose[:3, :3] = rot_y(side * slope)
        half = np.array([OCCLUDER_LENGTH_MM / 2.0, self.part.grasp_width_mm / 2.0, half_t])
        visual = robot_model.visual_shape(meshes.box(half, meshes.BODY_U), cid,
                                          [*OCCLUDER_COLOR, 1.0])
        collision = p.createCollisionShape(p.GEOM_BOX, halfExtents=(half / 1000.0).tolist(),
                                           physicsClientId=cid)
        body = p.createMultiBody(0.0, collision, visual, physicsClientId=cid)
        return _Item(body, pose, LABEL_OCCLUDER)

    def _seen_along_x(self, z_mm: float) -> np.ndarray:
        """Where the hand camera, at the pre-grasp pose, sees each vertex of the part on the
        plane ``z_mm`` above the table: x (mm) in the part's nominal grasp frame."""
        tool = _translation(0.0, 0.0, self.part.height_mm + APPROACH_HEIGHT_MM)
        tool[:3, :3] = tool_down_rotation(0.0)
        camera = (tool @ hand_camera.camera_in_tool(self.scene.camera.mount))[:3, 3]
        vertices = self.part.mesh.vertices_mm
        t = (z_mm - camera[2]) / (vertices[:, 2] - camera[2])
        return camera[0] + t * (vertices[:, 0] - camera[0])

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
        """The part's true rotational symmetry (``PartSpec.symmetry``): what the cell's own
        errors are wrapped by."""
        return self.part.symmetry

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
        """Whether the jaws hold the part: closed on it, and once lifted, carrying it."""
        return self._held is not None or self._gripping

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
        self._gripping = False
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
        grasp_physics.stop(self._client, body)

    @staticmethod
    def _heading_of(pose: np.ndarray) -> float:
        return math.degrees(math.atan2(pose[1, 0], pose[0, 0]))

    def _nominal_heading_deg(self, part_pose: np.ndarray) -> float:
        period = 360.0 / self.part.symmetry
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
        return step.dx_mm, step.dy_mm, wrap_deg(step.dphi_deg, 360.0 / self.part.symmetry)

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

        A move into the table or a part collides as a real arm would: the arm stops where the
        gripper (or a held part) is pushed ``max_penetration_mm`` into it, the wrist sensor
        feeling the contact force (``contact_stiffness_n_per_mm`` times that depth); nothing
        refuses it, the force guards must stop it. The first move after the jaws closed on
        the part is its lift: the part is held only if friction holds it
        (``grasp_physics.hold_test``), else it stays on the table.

        Raises MotionRejectedError, with nothing moved, when the target is out of reach or
        outside the joint limits.
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
        if self._gripping:
            self._lift_test()
        previous = (self._q_true, self._tool_true)
        travel = tool_true[:3, 3] - self._tool_true[:3, 3]
        if np.linalg.norm(travel) > 1e-6:
            self._motion_dir = travel / np.linalg.norm(travel)
        self._set_arm(q_true, tool_true)
        limit = self.arm_config.max_penetration_mm
        if self._deepest_mm() > limit:
            q_cmd, tool_cmd = self._stall(*previous, tool_true)
        self._q_cmd, self._tool_cmd = q_cmd, tool_cmd
        return self.arm_pose()

    def _deepest_mm(self) -> float:
        return max((c.depth_mm for c in self._touching()), default=0.0)

    def _stall(self, q_from: np.ndarray, tool_from: np.ndarray,
               tool_to: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The arm ran into something on its way from ``tool_from`` to ``tool_to``: put it
        where the deepest contact reaches ``max_penetration_mm`` (the servos stall there) and
        return that pose as the one reached (joints, tool)."""
        limit = self.arm_config.max_penetration_mm
        lo, hi = 0.0, 1.0
        q_lo, tool_lo = q_from, tool_from
        for _ in range(14):
            mid = (lo + hi) / 2.0
            tool = _interpolate(tool_from, tool_to, mid)
            try:
                q = puma260.inverse_kinematics(tool @ FLANGE_IN_TOOL, q_lo)
            except MotionRejectedError:
                hi = mid
                continue
            self._set_arm(q, tool)
            if self._deepest_mm() > limit:
                hi = mid
            else:
                lo, q_lo, tool_lo = mid, q, tool
        self._set_arm(q_lo, tool_lo)
        force = self.arm_config.contact_stiffness_n_per_mm * self._deepest_mm()
        logger.warning("collision: the arm ran into an obstacle and stalled after %.0f%% of "
                       "the move, pressing with about %.0f N", 100.0 * lo, force)
        return q_lo, tool_lo

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
        """Open the jaws to the part's jaw opening, letting go of a held part (it falls and
        comes to rest as physics has it)."""
        released = self._held is not None or self._gripping
        self._held, self._gripping = None, False
        self._set_fingers(self.part.jaw_opening_mm / 2.0)
        if released:
            grasp_physics.stop(self._client, self._part.body_id)
            grasp_physics.settle(self._jaws, self._q_true, self._part.body_id,
                                 self._finger_offset_mm)
            self._sync_part()
        return self.finger_width_mm()

    def close_gripper(self) -> float:
        """Close the jaws under position and force control (``grip_force_n``) until they stop
        on the part or meet; returns the finger width (mm). A finger closing off-centre
        pushes, turns or tilts the part (``grasp_physics.close_jaws``)."""
        if self._held is not None or self._gripping:
            return self.finger_width_mm()
        grasp_physics.stop(self._client, self._part.body_id)
        offset = grasp_physics.close_jaws(self._jaws, self._q_true, self.arm_config.grip_force_n)
        self._sync_part()
        self._set_fingers(max(offset, 0.0))
        self._gripping = all(grasp_physics.touching_fingers(self._jaws, self._part.body_id))
        return self.finger_width_mm()

    def _lift_test(self) -> None:
        """The lift begins: the part is held if friction holds it against its weight with the
        table's support gone; otherwise it stays behind on the table."""
        self._gripping = False
        before = self._part_pose.copy()
        supports = [self._table_id, *(item.body_id for item in self._clutter)]
        held = grasp_physics.hold_test(self._jaws, self._q_true, self._part.body_id, supports,
                                       self.arm_config.grip_force_n)
        if held:
            self._sync_part()
            self._held = np.linalg.inv(self._tool_true) @ self._part_pose
        else:
            logger.info("grasp: the part slid out of the jaws as they lifted")
            self._set_part_pose(before)
            grasp_physics.settle(self._jaws, self._q_true, self._part.body_id,
                                 self._finger_offset_mm, max_s=0.3)
            self._sync_part()
        self._set_fingers(self._finger_offset_mm)

    def _sync_part(self) -> None:
        """Take the part's pose from the physics (after the cell stepped it)."""
        pos, orn = p.getBasePositionAndOrientation(self._part.body_id,
                                                   physicsClientId=self._client)
        pose = np.eye(4)
        pose[:3, :3] = np.reshape(p.getMatrixFromQuaternion(orn), (3, 3))
        pose[:3, 3] = np.asarray(pos) * 1000.0
        self._set_part_pose(pose)

    def grasp_misalignment(self) -> dict[str, float] | None:
        """How the held part sits in the jaws, against sitting squarely centred between them
        (None when nothing is held): across_mm (along the jaw axis, tool y), along_mm (along
        the jaws, tool x), height_mm (along the approach axis, against the taught grip
        depth), phi_deg (turn about the approach axis, wrapped by the part's symmetry) and
        tilt_deg (of the part's vertical against the approach axis)."""
        if self._held is None:
            return None
        part_in_tool = self._held
        nominal = tool_down_rotation(0.0)  # the part's frame in the tool frame when square
        rel = nominal.T @ part_in_tool[:3, :3]
        grip_z = self.part.height_mm - self.part.grip_below_top_mm  # part origin, tool z
        return {
            "across_mm": float(part_in_tool[1, 3]),
            "along_mm": float(part_in_tool[0, 3]),
            "height_mm": float(part_in_tool[2, 3] - grip_z),
            "phi_deg": wrap_deg(math.degrees(math.atan2(rel[1, 0], rel[0, 0])),
                                360.0 / self.part.symmetry),
            "tilt_deg": math.degrees(math.acos(float(np.clip(rel[2, 2], -1.0, 1.0)))),
        }

    def _set_fingers(self, offset_mm: float) -> None:
        self._finger_offset_mm = offset_mm
        self._robot.set_fingers(offset_mm)
        self._contacts = None

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
                                   sensor, t[:3, :3], loads, self._motion_dir,
                                   grasp_physics.FINGER_PAD_FRICTION)
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

    @property
    def camera_mount(self) -> MountConfig:
        """How the hand camera sits on the gripper (the change from the standard mount)."""
        return self._mount

    def set_camera_mount(self, mount: MountConfig) -> None:
        """Move the hand camera on the gripper (a knock; ``scene.camera.mount`` at start)."""
        self._mount = mount

    def camera_to_world(self) -> np.ndarray:
        """4x4 pose (mm) of the hand camera (x right, y down, z forward)."""
        return self._tool_true @ hand_camera.camera_in_tool(self._mount)

    def _render_camera(self) -> np.ndarray:
        """4x4 pose (mm) of the camera the scene is rendered through: the hand camera, turned
        about its axis by the lens's ``sample_roll_deg`` (``optics.LensGeometry``)."""
        cam = self.camera_to_world()
        if self._optics is None:
            return cam
        return cam @ self._optics.geometry.render_in_camera()

    def _render_samples(self, light: Light | None = None
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The pinhole render at ``pixel_samples`` x ``pixel_samples`` samples a pixel
        (display-referred uint8 RGB, depth buffer, body ids) shaded by ``light`` (default: the
        cell's, without its further lamps): the delivered image's size, or the wider one the
        lens's distortion is resampled from (``optics.LensGeometry``)."""
        light = self.light if light is None else light
        if self._optics is None:
            width, height = hand_camera.WIDTH_PX, hand_camera.HEIGHT_PX
            projection = hand_camera.projection_matrix()
        else:
            geometry = self._optics.geometry
            width, height = geometry.width_px, geometry.height_px
            projection = geometry.projection_matrix()
        n = self.camera_model.pixel_samples
        _, _, rgba, depth, seg = p.getCameraImage(
            width * n, height * n, hand_camera.view_matrix(self._render_camera()), projection,
            lightDirection=list(light.direction), lightColor=list(light.color),
            lightAmbientCoeff=light.ambient, lightDiffuseCoeff=light.diffuse,
            lightSpecularCoeff=light.specular, shadow=0, renderer=p.ER_TINY_RENDERER,
            physicsClientId=self._client)
        shape = (height * n, width * n)
        rgb = np.reshape(np.asarray(rgba, dtype=np.uint8), (*shape, 4))[:, :, :3]
        depth = np.reshape(np.asarray(depth, dtype=np.float32), shape)
        seg = np.reshape(np.asarray(seg, dtype=np.int32), shape)
        return rgb, depth, seg

    def render(self, noisy: bool = True) -> np.ndarray:
        """What the hand camera sees: HxWx3 uint8 RGB (192x144), with cast shadows, through
        the configured optics and sensor (``optics``) and, when ``noisy``, with its noise.

        Each sample is shaded, its cast shadow included, before a pixel integrates the light
        of its samples (``optics.integrate_samples``): a pixel on the part's outline holds
        the part's light and the table's, each as lit where it lies. Each further lamp of the
        light is shaded and shadowed in a pass of its own, and the passes add up. Frames of a
        scene that has not changed since the last one (the arm, the part, the fingers, the
        light and the mount where they were) reuse its shaded samples; only the sensor's
        noise and exposure are new."""
        key = self._scene_key()
        if self._shaded is not None and self._shaded[0] == key:
            rgb = self._shaded[1]
        else:
            rgb, depth, seg = self._render_samples()
            rgb = self._shadowed(rgb, depth, seg, self.light)
            for lamp in self.light.lamps:
                more = self._shadowed(self._render_samples(lamp)[0], depth, seg, lamp)
                rgb = np.minimum(rgb.astype(np.uint16) + more, 255).astype(np.uint8)
            self._shaded = (key, rgb)
        if self._optics is not None:
            return self._optics.process_light(
                optics.integrate_samples(rgb, self.camera_model.pixel_samples), noisy)
        std = self.scene.camera.noise_std
        if noisy and std > 0:
            noise = self._noise_rng.standard_normal(rgb.shape, dtype=np.float32) * std
            rgb = np.clip(rgb + noise + 0.5, 0, 255).astype(np.uint8)
        return np.ascontiguousarray(rgb)

    def _scene_key(self) -> bytes:
        """What a render depends on: the arm's true joints and tool, the part's pose and the
        fingers' in the physics (they move while the jaws close and hold), the light and the
        camera's mount."""
        position, orientation = p.getBasePositionAndOrientation(self._part.body_id,
                                                                physicsClientId=self._client)
        fingers = [state[0] for state in p.getJointStates(
            self._robot.body_id, list(FINGER_LINKS), physicsClientId=self._client)]
        return b"".join((self._q_true.tobytes(), self._tool_true.tobytes(),
                         np.asarray((*position, *orientation, *fingers)).tobytes(),
                         repr((self._finger_offset_mm, self.light, self._mount)).encode()))

    def _shadowed(self, rgb: np.ndarray, depth: np.ndarray, seg: np.ndarray,
                  light: Light) -> np.ndarray:
        """A render's samples with the cast shadows of ``light`` shaded in."""
        if not light.casts_shadows:
            return rgb
        cam = self._render_camera()
        rays = None if self._optics is None else self._optics.geometry.sample_rays()
        return self._shadow_map.apply(rgb, depth, seg, cam, light, self._shadow_centre(cam),
                                      self._table_rgba, rays)

    @property
    def exposure_factor(self) -> float:
        """The camera's exposure x gain now (1 for the ideal camera, which has none)."""
        return 1.0 if self._optics is None else self._optics.factor

    def visible_fraction(self) -> float:
        """The share of the part's pixels the hand camera sees from where it is now, the
        occluder in place against the occluder taken away (1 without an occluder)."""
        if self._occluder is None:
            return 1.0
        seen = int((self.render_labels() == LABEL_PART).sum())
        self._place_body(self._occluder.body_id, _translation(0.0, 0.0, -5000.0))
        try:
            whole = int((self.render_labels() == LABEL_PART).sum())
        finally:
            self._set_part_pose(self._part_pose)
        return 1.0 if whole == 0 else min(1.0, seen / whole)

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
        _, _, seg = self._render_samples()
        n = self.camera_model.pixel_samples
        seg = np.ascontiguousarray(seg[n // 2::n, n // 2::n])  # the sample at a pixel's centre
        if self._optics is not None:
            seg = self._optics.geometry.resample(seg, nearest=True)
        out = np.full(seg.shape, LABEL_BACKGROUND, dtype=np.int32)
        for body, label in self._labels.items():
            out[seg == body] = label
        return out
