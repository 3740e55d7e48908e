"""The hand camera's optics and sensor: lens distortion, vignetting, blur, exposure, noise.

A real hand camera is no pinhole: ``CameraModel`` (resolved from ``scene.camera``, a preset with
any explicit value overriding it) describes its lens and sensor, ``LensGeometry`` the wider
pinhole render the distorted image is resampled from, and ``CameraPipeline`` turns each render
into the frame the camera delivers, keeping the auto-exposure's state from frame to frame.

The pipeline, per frame:

1. the renderer's samples, cast shadows shaded in, are taken as display-referred (gamma
   ``DISPLAY_GAMMA``), and each pixel's are averaged in linear light (``integrate_samples``);
2. lens (the render, its samples on a grid turned by ``sample_roll_deg`` against the
   pixels, resampled through): the distortion (OpenCV's model:
   ``x_d = x (1 + k1 r^2 + k2 r^4) + 2 p1 x y + p2 (r^2 + 2 x^2)``,
   ``y_d = y (1 + k1 r^2 + k2 r^4) + p1 (r^2 + 2 y^2) + 2 p2 x y`` on normalised coordinates,
   camera matrix ``[[f, 0, cx], [0, f, cy], [0, 0, 1]]`` with
   ``cx = W/2 - 0.5``, ``cy = H/2 - 0.5`` in OpenCV's pixel convention), defocus (a Gaussian
   blur) and vignetting (light falling off with the squared distance from the image centre,
   corners losing ``vignetting``);
3. exposure x gain (auto-exposure: each frame moves the factor by ``speed`` of the log error
   between the frame's mean grey and ``target_grey``, so it follows a change of light over a
   few frames; the exposure time grows up to ``MAX_EXPOSURE`` times the nominal one before the
   gain, up to ``max_gain``, amplifies signal and noise alike);
4. sensor: the Bayer mosaic (if on), shot noise (Poisson in electrons, from ``full_well_e``),
   saturation;
5. the camera's gamma, read noise (``noise_std`` grey levels of the delivered frame, as the
   ideal camera's, times the gain), 8-bit quantisation, demosaicing (OpenCV's bilinear), JPEG.

The ``ideal`` preset with nothing overridden is the pinhole camera with additive Gaussian noise
that ``SimCell`` renders directly (``CameraModel.ideal``); this module is then not used.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import cv2
import numpy as np

from sim_backend.cell import hand_camera

DISPLAY_GAMMA = 2.2  # the renderer's output taken as display-referred with this gamma

# A small industrial colour camera (1/3" CMOS behind an M12 lens of about 52 deg vertical
# field, its frame binned down to 192x144): moderate barrel distortion with a slight
# decentring, 30 % light fall-off in the corners, half a pixel of defocus, a 6000 e- full well
# (shot noise) over 2 grey levels of read noise, an sRGB-like output gamma and auto-exposure
# settling within about five frames. Industrial cameras deliver uncompressed frames (no JPEG),
# and a colour sensor's mosaic is demosaiced at its full resolution, before binning: at
# 192x144 no mosaic pattern is left (bayer: true demosaics at the delivered resolution, a
# camera without binning). Each pixel integrates the light over its area (the renderer takes
# pixel_samples x pixel_samples samples a pixel, each shaded and shadowed, and their light is
# averaged: ``integrate_samples``): an edge across a pixel gives a grey in between, so the
# part's outline moves in fractions of a pixel, as on a real sensor; one sample a pixel snaps
# every edge to the pixel grid. The samples' grid is turned by sample_roll_deg against the
# pixels, so that an edge along the pixel rows also moves smoothly (``LensGeometry``).
REALISTIC = {
    "fov_deg": hand_camera.VFOV_DEG, "k1": -0.15, "k2": 0.03, "p1": 0.0005, "p2": -0.0005,
    "vignetting": 0.3, "blur_px": 0.5, "full_well_e": 6000.0, "gamma": 2.2, "bayer": False,
    "jpeg_quality": 0, "auto": True, "target_grey": 110.0, "speed": 0.5, "gain": 1.0,
    "max_gain": 8.0, "pixel_samples": 2, "sample_roll_deg": 7.0,
}
# Today's pinhole camera: no lens effects, fixed unit exposure, Gaussian noise only.
IDEAL = {
    "fov_deg": hand_camera.VFOV_DEG, "k1": 0.0, "k2": 0.0, "p1": 0.0, "p2": 0.0,
    "vignetting": 0.0, "blur_px": 0.0, "full_well_e": 0.0, "gamma": DISPLAY_GAMMA,
    "bayer": False, "jpeg_quality": 0, "auto": False, "target_grey": 110.0, "speed": 0.5,
    "gain": 1.0, "max_gain": 8.0, "pixel_samples": 1, "sample_roll_deg": 0.0,
}
PRESETS = {"realistic": REALISTIC, "ideal": IDEAL}
_MIN_FACTOR = 0.02  # the smallest exposure x gain auto-exposure goes to
# The longest exposure, relative to the nominal one (factor 1): a 10 ms exposure may grow to
# about 30 ms within a 30 frames/s period before the gain (and with it the noise) goes up.
MAX_EXPOSURE = 3.0


@dataclass(frozen=True)
class CameraModel:
    """Every optics and sensor value, resolved (see ``scene_config.CameraConfig`` for their
    meaning); ``auto``, ``target_grey``, ``speed``, ``gain``, ``max_gain`` are the
    exposure's."""

    fov_deg: float
    k1: float
    k2: float
    p1: float
    p2: float
    vignetting: float
    blur_px: float
    noise_std: float
    full_well_e: float
    gamma: float
    bayer: bool
    jpeg_quality: int
    auto: bool
    target_grey: float
    speed: float
    gain: float
    max_gain: float
    pixel_samples: int
    sample_roll_deg: float

    @property
    def ideal(self) -> bool:
        """Whether this is the plain pinhole camera with additive Gaussian noise only."""
        base = {k: v for k, v in IDEAL.items()}
        return all(getattr(self, k) == v for k, v in base.items())

    @property
    def focal_px(self) -> float:
        """Focal length in pixels of the (undistorted) image."""
        return (hand_camera.HEIGHT_PX / 2.0) / math.tan(math.radians(self.fov_deg) / 2.0)

    @property
    def distortion(self) -> np.ndarray:
        """OpenCV's distortion vector (k1, k2, p1, p2)."""
        return np.array([self.k1, self.k2, self.p1, self.p2])

    def camera_matrix(self) -> np.ndarray:
        """OpenCV's 3x3 camera matrix of the delivered image (pixel centres at integers)."""
        f = self.focal_px
        return np.array([[f, 0.0, hand_camera.WIDTH_PX / 2.0 - 0.5],
                         [0.0, f, hand_camera.HEIGHT_PX / 2.0 - 0.5], [0.0, 0.0, 1.0]])

    def as_dict(self) -> dict:
        """The values by name (for reports)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


def resolve_camera(config) -> CameraModel:
    """The CameraModel of a ``scene_config.CameraConfig``: the preset's values, overridden by
    every value the config gives.

    Raises:
        ValueError: the lens folds the image (distortion not one-to-one over the image).
    """
    values = dict(PRESETS[config.preset])
    lens, exposure = config.lens, config.exposure
    for source, names in ((lens, ("fov_deg", "k1", "k2", "p1", "p2", "vignetting", "blur_px")),
                          (exposure, ("auto", "target_grey", "speed", "gain", "max_gain")),
                          (config, ("bayer", "jpeg_quality", "gamma", "full_well_e",
                                    "pixel_samples", "sample_roll_deg"))):
        for name in names:
            value = getattr(source, name)
            if value is not None:
                values[name] = value
    model = CameraModel(noise_std=config.noise_std, **values)
    check_lens(model)
    return model


def distort_normalized(x: np.ndarray, y: np.ndarray, k: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's distortion of normalised coordinates (x, y) with k = (k1, k2, p1, p2)."""
    k1, k2, p1, p2 = k
    r2 = x * x + y * y
    radial = 1.0 + k1 * r2 + k2 * r2 * r2
    return (x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y)


def undistort_normalized(xd: np.ndarray, yd: np.ndarray, k: np.ndarray, iterations: int = 30
                         ) -> tuple[np.ndarray, np.ndarray]:
    """The normalised coordinates that ``distort_normalized`` maps to (xd, yd) (Newton's
    method on the full model, from the distorted point)."""
    x, y = np.array(xd, dtype=float), np.array(yd, dtype=float)
    eps = 1e-7
    for _ in range(iterations):
        fx, fy = distort_normalized(x, y, k)
        ex, ey = fx - xd, fy - yd
        ax, ay = distort_normalized(x + eps, y, k)
        bx, by = distort_normalized(x, y + eps, k)
        j11, j21 = (ax - fx) / eps, (ay - fy) / eps
        j12, j22 = (bx - fx) / eps, (by - fy) / eps
        det = j11 * j22 - j12 * j21
        det = np.where(np.abs(det) < 1e-12, 1e-12, det)
        x = x - (j22 * ex - j12 * ey) / det
        y = y - (-j21 * ex + j11 * ey) / det
    return x, y


def project_points(points_cam_mm: np.ndarray, model: CameraModel) -> np.ndarray:
    """Pixel coordinates (OpenCV's convention) of camera-frame points through the lens."""
    p = np.atleast_2d(np.asarray(points_cam_mm, dtype=float))
    xd, yd = distort_normalized(p[:, 0] / p[:, 2], p[:, 1] / p[:, 2], model.distortion)
    k = model.camera_matrix()
    return np.c_[k[0, 0] * xd + k[0, 2], k[1, 1] * yd + k[1, 2]]


def _border_normalized(model: CameraModel) -> tuple[np.ndarray, np.ndarray]:
    """Distorted normalised coordinates of points along the delivered image's border."""
    w, h = hand_camera.WIDTH_PX, hand_camera.HEIGHT_PX
    k = model.camera_matrix()
    u = np.r_[np.linspace(-0.5, w - 0.5, 97), np.full(73, -0.5), np.full(73, w - 0.5),
              np.linspace(-0.5, w - 0.5, 97)]
    v = np.r_[np.full(97, -0.5), np.linspace(-0.5, h - 0.5, 73), np.linspace(-0.5, h - 0.5, 73),
              np.full(97, h - 0.5)]
    return (u - k[0, 2]) / k[0, 0], (v - k[1, 2]) / k[1, 1]


def check_lens(model: CameraModel) -> None:
    """Raise ValueError when the distortion is not one-to-one out to the image's corners
    (the radial factor must grow with the radius there, as in any real lens)."""
    xd, yd = _border_normalized(model)
    r_max = float(np.hypot(xd, yd).max()) * 1.6
    r = np.linspace(0.0, r_max, 400)
    k1, k2 = model.k1, model.k2
    rd = r * (1.0 + k1 * r**2 + k2 * r**4)
    slope = 1.0 + 3.0 * k1 * r**2 + 5.0 * k2 * r**4
    reach = rd >= float(np.hypot(xd, yd).max())
    first = int(np.argmax(reach)) if reach.any() else len(r)
    if first == len(r) or (slope[: first + 1] <= 0.05).any():
        raise ValueError(f"lens: k1 {k1:g}, k2 {k2:g} fold the image before its corners "
                         f"(the distortion is not one-to-one at fov_deg {model.fov_deg:g}); "
                         "a stronger barrel (k1 < 0) needs a positive k2")
    xu, yu = undistort_normalized(xd, yd, model.distortion)
    fx, fy = distort_normalized(xu, yu, model.distortion)
    if not np.allclose(np.c_[fx, fy], np.c_[xd, yd], atol=1e-6):
        raise ValueError(f"lens: k1 {k1:g}, k2 {k2:g}, p1 {model.p1:g}, p2 {model.p2:g} "
                         "cannot be inverted over the image")


class LensGeometry:
    """The pinhole render a distorted image is resampled from, and the resampling maps.

    The render has the delivered image's focal length and is just wide enough to cover every
    delivered pixel's undistorted ray (so a barrel lens sees more than the pinhole would).
    With ``sample_roll_deg`` it is taken by a camera turned by that much about the optical
    axis, and the maps turn it back: its samples (``pixel_samples`` per pixel side) then lie
    on a grid turned against the sensor's pixels, and an edge parallel to the pixel rows
    covers them one after another as it moves instead of a whole row of them at once
    (rotated-grid supersampling).

    Attributes:
        width_px, height_px: the render's size; vfov_deg: its vertical field of view.
        map_u, map_v: (H, W) float32 render coordinates of each delivered pixel (cv2.remap).
        vignette: (H, W) float32 light factor of each delivered pixel.
    """

    def __init__(self, model: CameraModel) -> None:
        self.model = model
        f = model.focal_px
        k = model.camera_matrix()
        w, h = hand_camera.WIDTH_PX, hand_camera.HEIGHT_PX
        roll = math.radians(model.sample_roll_deg)
        self._roll = (math.cos(roll), math.sin(roll))
        xd, yd = _border_normalized(model)
        xb, yb = self._rolled(*undistort_normalized(xd, yd, model.distortion))
        half_w = max(float(np.abs(xb).max()) * f, w / 2.0)
        half_h = max(float(np.abs(yb).max()) * f, h / 2.0)
        self.width_px = 2 * math.ceil(half_w + 2.0)
        self.height_px = 2 * math.ceil(half_h + 2.0)
        self.focal_px = f
        self.vfov_deg = 2.0 * math.degrees(math.atan(self.height_px / 2.0 / f))
        v, u = np.mgrid[0:h, 0:w].astype(float)
        xu, yu = self._rolled(*undistort_normalized((u - k[0, 2]) / f, (v - k[1, 2]) / f,
                                                     model.distortion))
        self.map_u = (xu * f + self.width_px / 2.0 - 0.5).astype(np.float32)
        self.map_v = (yu * f + self.height_px / 2.0 - 0.5).astype(np.float32)
        r2 = (u - k[0, 2]) ** 2 + (v - k[1, 2]) ** 2
        r2_corner = (w / 2.0) ** 2 + (h / 2.0) ** 2
        self.vignette = (1.0 - model.vignetting * r2 / r2_corner).astype(np.float32)
        self._rays: np.ndarray | None = None

    def _rolled(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The render's normalised coordinates of the camera's (x, y): the render is the
        camera turned by ``sample_roll_deg`` about its optical axis."""
        c, s = self._roll
        return c * x + s * y, -s * x + c * y

    def render_in_camera(self) -> np.ndarray:
        """4x4 pose of the render's camera in the camera's frame: turned by
        ``sample_roll_deg`` about the optical axis (x towards y), so that its sample rows
        cross the sensor's pixel rows."""
        c, s = self._roll
        t = np.eye(4)
        t[:2, :2] = [[c, -s], [s, c]]
        return t

    def projection_matrix(self) -> list[float]:
        """The render's projection for PyBullet's getCameraImage."""
        return hand_camera.perspective(self.vfov_deg, self.width_px / self.height_px,
                                       hand_camera.NEAR_MM, hand_camera.FAR_MM)

    def sample_rays(self) -> np.ndarray:
        """(H n, W n, 3) camera-frame rays through the render's samples, ``pixel_samples`` (n)
        a pixel side (for the shadow map, which shades each sample)."""
        if self._rays is None:
            n = self.model.pixel_samples
            self._rays = hand_camera.pixel_rays(self.width_px * n, self.height_px * n,
                                                self.focal_px * n)
        return self._rays

    def resample(self, image: np.ndarray, nearest: bool = False) -> np.ndarray:
        """The render ``image`` seen through the lens: the delivered (144x192) image."""
        mode = cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR
        if image.dtype == np.int32:  # labels: cv2.remap takes no int32
            return cv2.remap(image.astype(np.float32), self.map_u, self.map_v, mode,
                             borderMode=cv2.BORDER_REPLICATE).astype(np.int32)
        return cv2.remap(image, self.map_u, self.map_v, mode, borderMode=cv2.BORDER_REPLICATE)


class CameraPipeline:
    """Turns renders into delivered frames (module docstring), keeping the exposure state.

    Args:
        model: the camera.
        rng: the noise generator (seeded by the cell).
    """

    def __init__(self, model: CameraModel, rng: np.random.Generator) -> None:
        self.model = model
        self.geometry = LensGeometry(model)
        self._rng = rng
        self.factor = model.gain  # exposure x gain
        self.last_mean_grey: float | None = None

    def process(self, render_rgb: np.ndarray, noisy: bool = True) -> np.ndarray:
        """The frame (144x192x3 uint8 RGB) for one render (the render's size, uint8 RGB
        display-referred levels, ``DISPLAY_GAMMA``); updates the auto-exposure."""
        return self.process_light(_DECODE[render_rgb], noisy)

    def process_light(self, light: np.ndarray, noisy: bool = True) -> np.ndarray:
        """``process`` for a render already in linear light (the render's size, RGB float32
        0..1: ``integrate_samples``)."""
        m = self.model
        linear = self.geometry.resample(light)
        if m.blur_px > 0:
            linear = cv2.GaussianBlur(linear, (0, 0), m.blur_px)
        linear = linear * self.geometry.vignette[:, :, None]
        exposure = min(self.factor, MAX_EXPOSURE)  # exposure time tops out; gain does the rest
        gain = self.factor / exposure
        signal = linear * exposure  # fraction of the full well
        if m.bayer:
            signal = mosaic(signal)
        if noisy and m.full_well_e > 0:
            electrons = np.clip(signal, 0.0, 1.0) * m.full_well_e
            electrons = electrons + np.sqrt(electrons) * self._rng.standard_normal(
                electrons.shape, dtype=np.float32)
            signal = electrons / m.full_well_e
        level = 255.0 * np.clip(signal * gain, 0.0, 1.0) ** (1.0 / m.gamma)
        if noisy and m.noise_std > 0:  # read noise: grey levels of the frame, times the gain
            level = level + self._rng.standard_normal(level.shape, dtype=np.float32) * (
                m.noise_std * gain)
        out = np.clip(level + 0.5, 0, 255).astype(np.uint8)
        if m.bayer:
            out = cv2.cvtColor(out, cv2.COLOR_BayerBG2RGB)
        self._update_exposure(float(out.mean()))
        if m.jpeg_quality > 0:
            ok, data = cv2.imencode(".jpg", out[:, :, ::-1],
                                    [cv2.IMWRITE_JPEG_QUALITY, int(m.jpeg_quality)])
            if not ok:
                raise RuntimeError("JPEG encoding failed")
            out = cv2.imdecode(data, cv2.IMREAD_COLOR)[:, :, ::-1]
        return np.ascontiguousarray(out)

    def _update_exposure(self, mean_grey: float) -> None:
        self.last_mean_grey = mean_grey
        m = self.model
        if not m.auto:
            return
        # The grey level responds to the factor through the gamma: correct in linear light.
        error = (m.target_grey / max(mean_grey, 1.0)) ** m.gamma
        self.factor = float(np.clip(self.factor * error ** m.speed, _MIN_FACTOR,
                                    MAX_EXPOSURE * m.max_gain))


def integrate_samples(rgb: np.ndarray, samples: int) -> np.ndarray:
    """Each pixel's light integrated over its area: the mean, in linear light, of the
    ``samples`` x ``samples`` display-referred (``DISPLAY_GAMMA``) samples of a render
    (H n x W n x 3 uint8), as linear light (H x W x 3 float32, 0..1;
    ``CameraPipeline.process_light``). Averaging the encoded levels instead would read an
    edge pixel half part, half table as darker than the mean of their light."""
    linear = _DECODE[rgb]
    if samples == 1:
        return linear
    height, width = rgb.shape[0] // samples, rgb.shape[1] // samples
    return linear.reshape(height, samples, width, samples, 3).mean(axis=(1, 3),
                                                                    dtype=np.float32)


_DECODE = ((np.arange(256) / 255.0) ** DISPLAY_GAMMA).astype(np.float32)


def mosaic(rgb: np.ndarray) -> np.ndarray:
    """The RGGB Bayer mosaic (H x W) of an H x W x 3 image: red at even rows and columns, blue
    at odd rows and columns, green elsewhere (OpenCV calls this pattern BayerBG)."""
    out = rgb[:, :, 1].copy()
    out[0::2, 0::2] = rgb[0::2, 0::2, 0]
    out[1::2, 1::2] = rgb[1::2, 1::2, 2]
    return out
