"""Cameras read through OpenCV (device, file or MJPEG/HTTP stream), delivering 192x144 RGB."""

from drivers.camera.config import OpenCvCameraConfig
from drivers.camera.driver import OpenCvCamera
from drivers.camera.frame_reader import FrameStats

__all__ = ["FrameStats", "OpenCvCamera", "OpenCvCameraConfig"]
