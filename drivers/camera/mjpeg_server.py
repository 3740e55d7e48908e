"""An MJPEG-over-HTTP server on 127.0.0.1 serving the frames of any Camera, as network cameras do.

The wire format the OpenCV camera driver reads (``drivers.camera.driver``), written once here;
the camera emulator (``finepos sim camera-stream``, ``sim_backend.emulators.mjpeg``) serves the
simulated hand camera with it. (The cell's live view is Foxglove's protocol:
``controller.recording.live``.)

Routes:

- ``/stream.mjpg``: ``multipart/x-mixed-replace; boundary=...``, one JPEG part per frame
  (each with ``Content-Type: image/jpeg`` and ``Content-Length``), for as long as the client
  stays connected;
- ``/snapshot.jpg``: one freshly grabbed frame.

Frames are grabbed on request: a single grabber thread takes frames at up to ``fps`` while at
least one stream client is connected and shares each encoded frame with all of them, so the
camera (e.g. the simulated hand camera) is never used from two threads at once. The caller owns
the camera's lifecycle (connect it first).

The source's states, the emulator's fault knobs: ``paused`` (an Event): while set, streams get
no frames (connections stay open), as with a network camera that hangs; ``set_gone(True)``: the
camera is gone (unplugged, rebooting): open streams end at once and every request is answered
503 until ``set_gone(False)``; ``refused`` counts the streams ended and requests refused that
way.
"""

from __future__ import annotations

import functools
import logging
import threading
from collections.abc import Callable
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Literal

import cv2

from drivers.core.errors import FineposError
from drivers.core.lifecycle import ThreadedServer
from drivers.interfaces import Camera

logger = logging.getLogger(__name__)

BOUNDARY = "finepos-frame"
STREAM_PATH = "/stream.mjpg"
SNAPSHOT_PATH = "/snapshot.jpg"
_CLIENT_SOCKET_TIMEOUT_S = 5.0  # a client that stops reading is dropped after this
_POLL_INTERVAL_S = 0.05  # how soon close() stops the accept loop
# A camera error, or a frame OpenCV cannot convert or encode (wrong dtype or shape).
_FRAME_ERRORS = (FineposError, cv2.error, ValueError)


_SAMPLING = {"444": cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444,
             "420": cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420}


class _Server(ThreadingHTTPServer):
    """Request threads are joined by ``server_close()`` (deterministic teardown)."""

    daemon_threads = False


class MjpegServer(ThreadedServer):
    """Serves ``camera`` on ``http://127.0.0.1:{port}``; use as a context manager."""

    def __init__(self, camera: Camera, port: int = 0, fps: float = 10.0,
                 jpeg_quality: int = 95, chroma: Literal["444", "420"] = "444") -> None:
        """``chroma``: JPEG chroma subsampling. 4:2:0 (what many network cameras send by
        default) halves the colour resolution, which moves the edge of a saturation-channel
        silhouette by a fraction of a pixel (about 0.2 mm of bias at the taught pose); 4:4:4
        at quality 95 matches raw frames within 0.05 mm."""
        if chroma not in _SAMPLING:
            raise ValueError(f"chroma must be 444 or 420, got {chroma!r}")
        super().__init__()
        self.camera = camera
        self.fps = fps
        self.jpeg_quality = jpeg_quality
        self.chroma = chroma
        self.paused = threading.Event()
        self.gone = threading.Event()
        self.refused = 0
        self.frames_grabbed = 0
        self._requested_port = port
        self._camera_lock = threading.Lock()
        self._frame_changed = threading.Condition()
        self._jpeg: bytes | None = None
        self._sequence = 0
        self._clients = 0
        self._httpd: _Server | None = None

    # -- addresses ------------------------------------------------------------------------
    @property
    def port(self) -> int:
        if self._httpd is None:
            raise RuntimeError("MjpegServer is not started")
        return self._httpd.server_address[1]

    @property
    def stream_url(self) -> str:
        return f"http://127.0.0.1:{self.port}{STREAM_PATH}"

    @property
    def snapshot_url(self) -> str:
        return f"http://127.0.0.1:{self.port}{SNAPSHOT_PATH}"

    # -- lifecycle ------------------------------------------------------------------------
    def _open(self) -> dict[str, Callable[[], object]]:
        self._httpd = _Server(("127.0.0.1", self._requested_port), _handler_class(self))
        logger.info("MJPEG stream on %s", self.stream_url)
        return {"http": functools.partial(self._httpd.serve_forever, _POLL_INTERVAL_S),
                "grabber": self._grab_loop}

    def _interrupt(self) -> None:
        """End every stream and the grabber, and stop accepting."""
        with self._frame_changed:
            self._frame_changed.notify_all()
        assert self._httpd is not None
        self._httpd.shutdown()

    def _release(self) -> None:
        assert self._httpd is not None
        self._httpd.server_close()  # joins the request threads
        self._httpd = None

    def set_gone(self, gone: bool) -> None:
        """Take the camera away (open streams end, requests get 503) or bring it back."""
        with self._frame_changed:
            (self.gone.set if gone else self.gone.clear)()
            self._frame_changed.notify_all()
        logger.info("MJPEG camera %s", "gone" if gone else "back")

    def _refuse(self) -> None:
        with self._frame_changed:
            self.refused += 1

    # -- frames ---------------------------------------------------------------------------
    def grab_jpeg(self) -> bytes:
        """Grab one frame from the camera now and encode it.

        Raises the camera's errors, and cv2.error or ValueError for a frame that cannot be
        converted or encoded.
        """
        with self._camera_lock:
            frame = self.camera.grab()
            self.frames_grabbed += 1
        ok, data = cv2.imencode(".jpg", cv2.cvtColor(frame.image, cv2.COLOR_RGB2BGR),
                                [cv2.IMWRITE_JPEG_QUALITY, self.jpeg_quality,
                                 cv2.IMWRITE_JPEG_SAMPLING_FACTOR, _SAMPLING[self.chroma]])
        if not ok:
            raise ValueError(f"JPEG encoding failed for a {frame.image.shape} frame")
        return data.tobytes()

    def _grab_loop(self) -> None:
        period_s = 1.0 / self.fps
        while True:
            with self._frame_changed:
                self._frame_changed.wait_for(lambda: self._closing.is_set() or self._clients > 0)
                if self._closing.is_set():
                    return
            if not self.paused.is_set():
                try:
                    jpeg = self.grab_jpeg()
                except _FRAME_ERRORS as exc:
                    logger.warning("MJPEG: no frame to send: %s", exc)
                else:
                    with self._frame_changed:
                        self._jpeg = jpeg
                        self._sequence += 1
                        self._frame_changed.notify_all()
            with self._frame_changed:
                if self._frame_changed.wait_for(self._closing.is_set, period_s):
                    return

    def _next_jpeg(self, after_sequence: int) -> tuple[int, bytes] | None:
        """Block until a frame newer than ``after_sequence``; None when the server closes or
        the camera is gone."""
        with self._frame_changed:
            self._frame_changed.wait_for(lambda: self._closing.is_set() or self.gone.is_set()
                                         or self._sequence > after_sequence)
            if self._closing.is_set() or self.gone.is_set():
                return None
            assert self._jpeg is not None
            return self._sequence, self._jpeg

    def _client_joined(self, delta: int) -> int:
        """Count stream clients; returns the current frame sequence number."""
        with self._frame_changed:
            self._clients += delta
            self._frame_changed.notify_all()
            return self._sequence


def _handler_class(server: MjpegServer) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        timeout = _CLIENT_SOCKET_TIMEOUT_S

        def do_GET(self) -> None:  # noqa: N802 (http.server naming)
            path = self.path.split("?", 1)[0]
            if server.gone.is_set():
                server._refuse()
                self.send_error(HTTPStatus.SERVICE_UNAVAILABLE, "camera gone")
            elif path == STREAM_PATH:
                self._stream()
            elif path == SNAPSHOT_PATH:
                self._snapshot()
            else:
                self.send_error(HTTPStatus.NOT_FOUND, f"try {STREAM_PATH} or {SNAPSHOT_PATH}")

        def _snapshot(self) -> None:
            try:
                jpeg = server.grab_jpeg()
            except _FRAME_ERRORS as exc:
                self.send_error(HTTPStatus.SERVICE_UNAVAILABLE, f"camera: {exc}")
                return
            self.send_response(HTTPStatus.OK)
            self.send_header("Content-Type", "image/jpeg")
            self.send_header("Content-Length", str(len(jpeg)))
            self.send_header("Cache-Control", "no-cache")
            self.end_headers()
            self.wfile.write(jpeg)

        def _stream(self) -> None:
            self.send_response(HTTPStatus.OK)
            self.send_header("Content-Type", f"multipart/x-mixed-replace; boundary={BOUNDARY}")
            self.send_header("Cache-Control", "no-cache")
            self.send_header("Connection", "close")
            self.end_headers()
            sequence = server._client_joined(+1)
            try:
                while (item := server._next_jpeg(sequence)) is not None:
                    sequence, jpeg = item
                    self.wfile.write(
                        f"--{BOUNDARY}\r\nContent-Type: image/jpeg\r\n"
                        f"Content-Length: {len(jpeg)}\r\n\r\n".encode("ascii")
                        + jpeg + b"\r\n")
                    self.wfile.flush()
            except (ConnectionError, TimeoutError) as exc:
                logger.debug("MJPEG client %s left: %s", self.client_address, exc)
            finally:
                server._client_joined(-1)
            if server.gone.is_set():
                server._refuse()

        def log_message(self, format: str, *args) -> None:  # noqa: A002 (base signature)
            logger.debug("MJPEG %s: " + format, self.client_address[0], *args)

    return Handler
