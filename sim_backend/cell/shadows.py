"""Cast shadows for the hand-camera image: a shadow map rendered from the lamp.

TinyRenderer's own shadows are too faint for "a sideward lamp with hard cast shadows" (they
take away a fifth of the lamp's light) and skip everything within 5 cm of its occluder at our
scale, so the cell draws its own: the scene (without the table, which shadows nothing) is
rendered from the lamp, every camera pixel is located in space from the camera's depth buffer,
and where another body lies between it and the lamp (bilinear percentage-closer filtering over
the map's texels) the lamp's share of its brightness is taken away, ``shadow_strength`` of it.
Bodies do not shadow themselves here: faces turned away from the lamp are already dark, and
the parts' holes are darkened by their texture.

The lamp's share is computed for an upward-facing surface (exact for the table and the parts'
top faces). The lamp is a point 1.5 m away along the light direction.
"""

from __future__ import annotations

import math

import numpy as np

from sim_backend.cell import hand_camera
from sim_backend.cell.lighting import Light
from sim_backend.cell.pybullet_quiet import p

LAMP_DISTANCE_MM = 1500.0
MAP_SIZE_PX = 256
MAP_EXTENT_MM = 280.0  # the map covers this square around its centre
_NEAR_MM = LAMP_DISTANCE_MM - 700.0
_FAR_MM = LAMP_DISTANCE_MM + 300.0
_BIAS_MM = 1.0


def _look_at(eye_mm: np.ndarray, target_mm: np.ndarray) -> np.ndarray:
    """4x4 camera-to-world (OpenCV axes: x right, y down, z forward) looking at the target."""
    forward = (target_mm - eye_mm) / np.linalg.norm(target_mm - eye_mm)
    helper = np.array([1.0, 0.0, 0.0]) if abs(forward[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    right = np.cross(forward, helper)
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    t = np.eye(4)
    t[:3, :3] = np.column_stack([right, down, forward])
    t[:3, 3] = eye_mm
    return t


class ShadowMap:
    """Renders the lamp's view and darkens shadowed pixels of camera images."""

    def __init__(self, client_id: int, hidden_body_id: int) -> None:
        self._client = client_id
        self._hidden = hidden_body_id
        self._fov_deg = 2.0 * math.degrees(math.atan(MAP_EXTENT_MM / 2.0 / LAMP_DISTANCE_MM))
        self._focal_px = (MAP_SIZE_PX / 2.0) / math.tan(math.radians(self._fov_deg) / 2.0)
        self._projection = hand_camera.perspective(self._fov_deg, 1.0, _NEAR_MM, _FAR_MM)
        self._rays = hand_camera.pixel_rays().reshape(-1, 3).astype(np.float32)

    def _render_map(self, lamp_to_world: np.ndarray, hidden_rgba) -> tuple[np.ndarray, np.ndarray]:
        p.changeVisualShape(self._hidden, -1, rgbaColor=[*hidden_rgba[:3], 0.0],
                            physicsClientId=self._client)
        try:
            _, _, _, depth, seg = p.getCameraImage(
                MAP_SIZE_PX, MAP_SIZE_PX, hand_camera.view_matrix(lamp_to_world),
                self._projection, renderer=p.ER_TINY_RENDERER, shadow=0,
                physicsClientId=self._client)
        finally:
            p.changeVisualShape(self._hidden, -1, rgbaColor=list(hidden_rgba),
                                physicsClientId=self._client)
        depth = np.reshape(np.asarray(depth, dtype=np.float32), (MAP_SIZE_PX, MAP_SIZE_PX))
        seg = np.reshape(np.asarray(seg, dtype=np.int32), (MAP_SIZE_PX, MAP_SIZE_PX))
        return hand_camera.linear_depth_mm(depth, _NEAR_MM, _FAR_MM), seg

    def apply(self, rgb: np.ndarray, depth_buffer: np.ndarray, seg: np.ndarray,
              camera_to_world: np.ndarray, light: Light, centre_mm: np.ndarray,
              hidden_rgba, rays: np.ndarray | None = None) -> np.ndarray:
        """``rgb`` (H x W x 3 uint8) with the cast shadows of ``light`` darkened in.

        centre_mm: the point on the table the shadow map is centred on; hidden_rgba: the
        hidden body's colour, restored after the lamp's view is rendered; rays: (H, W, 3)
        camera-frame rays of the render's pixels (default: the standard hand-camera image's).
        """
        direction = np.asarray(light.direction)
        lamp = _look_at(centre_mm + direction * LAMP_DISTANCE_MM, centre_mm)
        map_depth, map_seg = self._render_map(lamp, hidden_rgba)
        # Camera pixels -> points in the lamp's frame, in one affine step.
        lamp_from_cam = np.linalg.inv(lamp) @ camera_to_world
        depth = hand_camera.depth_mm(depth_buffer.reshape(-1))
        rays = self._rays if rays is None else rays.reshape(-1, 3).astype(np.float32)
        pts = (rays * depth[:, None]) @ lamp_from_cam[:3, :3].T.astype(np.float32)
        pts += lamp_from_cam[:3, 3].astype(np.float32)
        z = pts[:, 2]
        scale = self._focal_px / z
        u = pts[:, 0] * scale + (MAP_SIZE_PX / 2.0 - 0.5)
        v = pts[:, 1] * scale + (MAP_SIZE_PX / 2.0 - 0.5)
        u0, v0 = np.floor(u), np.floor(v)
        fu, fv = u - u0, v - v0
        u0, v0 = u0.astype(np.int32), v0.astype(np.int32)
        receiver = seg.reshape(-1)
        flat_depth, flat_seg = map_depth.reshape(-1), map_seg.reshape(-1)
        amount = np.zeros(len(z), dtype=np.float32)
        last = MAP_SIZE_PX - 1
        for du, dv, w in ((0, 0, (1 - fu) * (1 - fv)), (1, 0, fu * (1 - fv)),
                          (0, 1, (1 - fu) * fv), (1, 1, fu * fv)):
            iu, iv = u0 + du, v0 + dv
            inside = (iu >= 0) & (iu <= last) & (iv >= 0) & (iv <= last)
            index = np.clip(iv, 0, last) * MAP_SIZE_PX + np.clip(iu, 0, last)
            occluder = flat_seg[index]
            blocked = (inside & (occluder >= 0) & (occluder != receiver)
                       & (flat_depth[index] + _BIAS_MM < z))
            amount += w * blocked
        amount[receiver < 0] = 0.0
        lamp_up = light.diffuse * max(direction[2], 0.0) * np.asarray(light.color)
        lit = light.ambient + lamp_up
        shadowed = light.ambient + (1.0 - light.shadow_strength) * lamp_up
        keep = np.where(lit > 0, shadowed / np.where(lit > 0, lit, 1.0), 1.0).astype(np.float32)
        factor = 1.0 - amount[:, None] * (1.0 - keep[None, :])
        out = rgb.reshape(-1, 3) * factor + 0.5
        return np.clip(out, 0, 255).astype(np.uint8).reshape(rgb.shape)
