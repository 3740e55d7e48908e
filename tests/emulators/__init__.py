"""Tests of the device emulators (ATI F/T controller, MJPEG camera stream, Magellan mouse)."""
