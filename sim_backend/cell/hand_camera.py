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


def _rotation(axis: int, angle_deg: float) -> np.ndarray:
    """Rotation by ``angle_deg`` about coordinate axis ``axis`` (0: x, 1: y, 2: z)."""
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    r = np.eye(3)
    r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
    return r


def camera_in_tool(mount=None) -> np.ndarray:
    """4x4 pose (mm) of the camera frame in the tool frame (z = approach axis).

    Args:
        mount: the change from the standard mount (``scene_config.MountConfig``: tilt about
            the image's x axis, which adds to TILT_DEG; pan about the image's y axis; roll
            about the optical axis; the lens moved by offset_mm in the tool frame); None or
            all zeros: the standard mount, exactly.
    """
    tilt = TILT_DEG + (mount.tilt_deg if mount is not None else 0.0)
    tau = math.radians(tilt)
    forward = np.array([math.sin(tau), 0.0, math.cos(tau)])
    down = np.array([-math.cos(tau), 0.0, math.sin(tau)])  # image down: back and towards z
    right = np.cross(down, forward)
    t = np.eye(4)
    t[:3, :3] = np.column_stack([right, down, forward])
    t[:3, 3] = LENS_IN_TOOL_MM
    if mount is not None:
        if mount.pan_deg or mount.roll_deg:
            t[:3, :3] = t[:3, :3] @ _rotation(1, mount.pan_deg) @ _rotation(2, mount.roll_deg)
        t[:3, 3] += np.asarray(mount.offset_mm, dtype=float)
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


def pixel_rays(width_px: int = WIDTH_PX, height_px: int = HEIGHT_PX,
               focal_px: float = FOCAL_PX) -> np.ndarray:
    """(H, W, 3) camera-frame directions through the pixel centres, with unit z (default: the
    standard image; other sizes and focal lengths for the optics' wider renders)."""
    v, u = np.mgrid[0:height_px, 0:width_px] + 0.5
    return np.dstack([(u - width_px / 2.0) / focal_px, (v - height_px / 2.0) / focal_px,
                      np.ones((height_px, width_px))])
