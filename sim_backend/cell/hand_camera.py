"""The hand camera: where it sits on the gripper, its optics, and the projection math.

192x144 RGB, fixed to the gripper 80 mm behind the tool axis and 45 mm above the fingertips,
looking forward and down, tilted 36 deg from the approach axis. At the pre-grasp pose (the
fingertips 35 mm above the cube) the fingertips show at the upper rim of the image and the
30 mm cube appears about 39 px wide just above the image centre; it stays fully in view, clear
of the fingertips, for tool displacements of +/-25 mm in x and y at any rotation.

Camera frame (OpenCV style): x right, y down, z along the optical axis. Lengths in mm except
the matrices handed to PyBullet (metres).
"""

from __future__ import annotations

import math

import numpy as np

WIDTH_PX = 192
HEIGHT_PX = 144
VFOV_DEG = 52.0
NEAR_MM = 5.0
FAR_MM = 1500.0
LENS_IN_TOOL_MM = (-80.0, 0.0, -45.0)
TILT_DEG = 36.0  # optical axis from the approach axis towards the tool's +x
FOCAL_PX = (HEIGHT_PX / 2.0) / math.tan(math.radians(VFOV_DEG) / 2.0)


def camera_in_tool() -> np.ndarray:
    """4x4 pose (mm) of the camera frame in the tool frame (z = approach axis)."""
    tau = math.radians(TILT_DEG)
    forward = np.array([math.sin(tau), 0.0, math.cos(tau)])
    down = np.array([-math.cos(tau), 0.0, math.sin(tau)])  # image down: back and towards z
    right = np.cross(down, forward)
    t = np.eye(4)
    t[:3, :3] = np.column_stack([right, down, forward])
    t[:3, 3] = LENS_IN_TOOL_MM
    return t


def project(points_mm: np.ndarray, camera_to_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates (u right, v down; pixel centres at .5) and depth (mm) of world points."""
    p = np.atleast_2d(np.asarray(points_mm, dtype=float))
    r, t = camera_to_world[:3, :3], camera_to_world[:3, 3]
    cam = (p - t) @ r
    z = cam[:, 2]
    uv = np.c_[WIDTH_PX / 2.0 + FOCAL_PX * cam[:, 0] / z,
               HEIGHT_PX / 2.0 + FOCAL_PX * cam[:, 1] / z]
    return uv, z


def view_matrix(camera_to_world: np.ndarray) -> list[float]:
    """OpenGL view matrix (column-major, metres) for PyBullet's getCameraImage."""
    gl = camera_to_world.copy()
    gl[:3, 1:3] *= -1.0  # OpenGL camera: y up, looking along -z
    gl[:3, 3] /= 1000.0
    return np.linalg.inv(gl).T.reshape(-1).tolist()


def perspective(vfov_deg: float, aspect: float, near_mm: float, far_mm: float) -> list[float]:
    """OpenGL perspective projection (column-major; PyBullet works in metres)."""
    near, far = near_mm / 1000.0, far_mm / 1000.0
    f = 1.0 / math.tan(math.radians(vfov_deg) / 2.0)
    m = np.zeros((4, 4))
    m[0, 0] = f / aspect
    m[1, 1] = f
    m[2, 2] = (far + near) / (near - far)
    m[2, 3] = 2.0 * far * near / (near - far)
    m[3, 2] = -1.0
    return m.T.reshape(-1).tolist()


def projection_matrix() -> list[float]:
    """The hand camera's projection for PyBullet's getCameraImage."""
    return perspective(VFOV_DEG, WIDTH_PX / HEIGHT_PX, NEAR_MM, FAR_MM)


def linear_depth_mm(depth_buffer: np.ndarray, near_mm: float, far_mm: float) -> np.ndarray:
    """Distance along the optical axis (mm) from a perspective render's [0, 1] depth buffer."""
    return far_mm * near_mm / (far_mm - (far_mm - near_mm) * depth_buffer)


def depth_mm(depth_buffer: np.ndarray) -> np.ndarray:
    """The hand camera's depth buffer as distance along its optical axis (mm)."""
    return linear_depth_mm(depth_buffer, NEAR_MM, FAR_MM)


def pixel_rays() -> np.ndarray:
    """(H, W, 3) camera-frame directions through the pixel centres, with unit z."""
    v, u = np.mgrid[0:HEIGHT_PX, 0:WIDTH_PX] + 0.5
    return np.dstack([(u - WIDTH_PX / 2.0) / FOCAL_PX, (v - HEIGHT_PX / 2.0) / FOCAL_PX,
                      np.ones((HEIGHT_PX, WIDTH_PX))])
