"""Replay a run recording: its looks with their overlays, as a video and as a contact sheet.

``read_looks`` pairs each recorded frame with its iteration record (same log time);
Both layouts a recording may have are read: images as protobuf ``foxglove.CompressedImage``
(what ``RunRecorder`` writes through the Foxglove SDK) or as its JSON encoding (a JSON Schema
layout), and iteration records as JSON. ``write_video`` writes one frame per look (MP4,
``mp4v``; ``hold_s`` repeats each so a player shows it long enough to read); ``write_sheet``
tiles the looks in a grid, in order.

A recording is input from outside: it is opened without blocking (a FIFO or device is refused),
each frame's size is read from its JPEG or PNG header before it is decoded, and every value
drawn or written is checked for its type and range first, so a damaged or hostile file is a
``RecordingError`` naming the file, the message and what is wrong. The video and the sheet are
written under a temporary name and renamed once complete, into a folder that must exist.
"""

from __future__ import annotations

import base64
import binascii
import contextlib
import json
import math
import os
import secrets
import stat
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from mcap.reader import make_reader

from controller.recording import protobuf
from controller.recording.channels import IMAGE_TOPIC, ITERATION_TOPIC, RecordingError
from controller.recording.overlay import Overlay, draw, look_texts
from drivers.core.files import atomic_write_bytes

MAX_FRAME_SIDE_PX = 4096  # a frame's width or height, read from its header before decoding
MAX_FRAMES_PX = 1 << 28  # all frames of a recording together (about 800 MB decoded)
MAX_COORD_PX = 1e5  # overlay coordinates (cv2 draws in int32 with 4 fraction bits, up to 8x)
MAX_VALUE = 1e9  # numbers written on a tile: mm, deg, counts
MAX_TEXT = 64  # characters of a text written on a tile (loop kind, status, run id)
_POINT = "a point [u, v]"


@dataclass
class Look:
    """One recorded look: the frame (HxWx3 RGB), its iteration record and overlay, log time."""

    log_time_ns: int
    image: np.ndarray
    record: dict[str, Any]
    overlay: Overlay

    def texts(self) -> list[str]:
        """The lines written on the look's tile (see ``overlay.look_texts``)."""
        lines = look_texts(self.record)
        error = self.record.get("error_at_look")
        if error:  # the error when the frame was taken; look_texts gives the one after
            lines = [line for line in lines if not line.startswith("true error")]
            lines.append(f"true error {error['x_mm']:+.2f} {error['y_mm']:+.2f} mm "
                         f"{error['phi_deg']:+.1f} deg")
        return lines


class _Bad(Exception):
    """What is wrong with one message (``read_looks`` adds the file and the message)."""


def read_looks(path: str | Path) -> list[Look]:
    """The looks of a recording, in log-time order.

    Raises:
        RecordingError: the file is missing, not a regular file, not MCAP, holds no looks, or a
            message in it is malformed (a frame too large or not JPEG/PNG, a record of the
            wrong shape): the message names the file and what is wrong.
    """
    path = Path(path)
    images: dict[int, np.ndarray] = {}
    records: dict[int, dict[str, Any]] = {}
    frames_px = 0
    first_size: tuple[int, int] | None = None
    where = None
    try:
        with _open_regular(path) as f:
            reader = make_reader(f)
            for _, channel, message in reader.iter_messages(
                    topics=[IMAGE_TOPIC, ITERATION_TOPIC]):
                where = f"the {channel.topic} message at {message.log_time} ns"
                if channel.topic == IMAGE_TOPIC:
                    data, image_format = _frame(channel.message_encoding, message.data)
                    size = _frame_size(data)
                    if first_size is not None and size != first_size:
                        raise _Bad(f"a {size[0]}x{size[1]} frame in a recording of "
                                   f"{first_size[0]}x{first_size[1]} frames")
                    first_size = size
                    frames_px += size[0] * size[1]
                    if frames_px > MAX_FRAMES_PX:
                        raise _Bad(f"the frames exceed {MAX_FRAMES_PX} pixels together")
                    bgr = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
                    if bgr is None or bgr.shape[1::-1] != size:
                        raise _Bad(f"the {image_format} frame does not decode")
                    images[message.log_time] = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
                else:
                    records[message.log_time] = _checked_record(json.loads(message.data))
    except FileNotFoundError:
        raise RecordingError(f"{path}: no such recording (record one with "
                             "'finepos position --record FILE.mcap')") from None
    except _Bad as exc:
        raise RecordingError(f"{path}: {where + ': ' if where else ''}{exc}") from None
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read the recording: "
                             f"{exc.strerror or exc}") from None
    except Exception as exc:
        # a damaged file, as the MCAP reader and its decompressors see it: McapError,
        # ZstdError, struct.error, EOFError, a JSON error...
        text = " ".join(str(exc).split())[:200]
        raise RecordingError(f"{path}: not a readable finepos recording ("
                             f"{where + ': ' if where else ''}{type(exc).__name__}: {text})"
                             ) from None
    looks = [Look(t, images[t], records[t], Overlay.from_dict(records[t].get("overlay") or {}))
             for t in sorted(images) if t in records]
    if not looks:
        raise RecordingError(f"{path}: the recording holds no looks")
    return looks


@contextlib.contextmanager
def _open_regular(path: Path):
    """The file at ``path`` opened for reading without blocking; refused unless a regular file
    (a FIFO would block, a device never end)."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    with os.fdopen(fd, "rb") as f:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise _Bad("not a regular file (a FIFO, device or directory)")
        yield f


def _frame(encoding: str, data: bytes) -> tuple[bytes, str]:
    """The encoded frame and its format of a ``foxglove.CompressedImage`` message, in either of
    its encodings: ``protobuf`` (the Foxglove SDK's) or ``json`` (the frame base64 in
    ``data``)."""
    if encoding == "protobuf":
        try:
            return protobuf.compressed_image(data)
        except ValueError as exc:
            raise _Bad(f"not a foxglove.CompressedImage: {exc}") from None
    if encoding != "json":
        raise _Bad(f"an image in the unknown message encoding {_show(encoding)}")
    body = json.loads(data)
    if not isinstance(body, dict) or not isinstance(body.get("data"), str):
        raise _Bad("expected an object with the frame as a base64 string in 'data'")
    try:
        return base64.b64decode(body["data"], validate=True), str(body.get("format"))
    except binascii.Error:
        raise _Bad("'data' is not base64") from None


def _frame_size(data: bytes) -> tuple[int, int]:
    """(width, height) of a JPEG or PNG frame, read from its header; checked against
    MAX_FRAME_SIDE_PX before anything is decoded."""
    if data.startswith(b"\x89PNG\r\n\x1a\n") and data[12:16] == b"IHDR" and len(data) >= 24:
        w, h = struct.unpack(">II", data[16:24])
    elif data.startswith(b"\xff\xd8"):
        w, h = _jpeg_size(data)
    else:
        raise _Bad("the frame is neither JPEG nor PNG")
    if not (0 < w <= MAX_FRAME_SIDE_PX and 0 < h <= MAX_FRAME_SIDE_PX):
        raise _Bad(f"the frame's header claims {w}x{h} pixels (at most "
                   f"{MAX_FRAME_SIDE_PX}x{MAX_FRAME_SIDE_PX})")
    return w, h


# JPEG start-of-frame markers (baseline, progressive, lossless, arithmetic): C0-CF but for DHT
# (C4), JPG (C8) and DAC (CC)
_SOF = set(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}


def _jpeg_size(data: bytes) -> tuple[int, int]:
    """(width, height) from a JPEG's first start-of-frame segment (the one decoders use)."""
    i = 2
    while i + 4 <= len(data):
        if data[i] != 0xFF:
            break
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker == 0x01 or 0xD0 <= marker <= 0xD7:  # no length
            i += 2
            continue
        if marker == 0xDA:  # start of scan before any frame header
            break
        (length,) = struct.unpack(">H", data[i + 2:i + 4])
        if marker in _SOF and i + 9 <= len(data):
            h, w = struct.unpack(">HH", data[i + 5:i + 9])
            return w, h
        i += 2 + length
    raise _Bad("the JPEG frame has no frame header")


def _checked_record(body: Any) -> dict[str, Any]:
    """An iteration record whose fields replay reads, checked for type and range."""
    if not isinstance(body, dict):
        raise _Bad(f"expected an iteration record (an object), got {_type(body)}")
    _number(body.get("iteration"), "iteration", MAX_VALUE, optional=True)
    if "loops" in body:  # written with a number format
        _number(body["loops"], "loops", MAX_VALUE)
    for key in ("loop_kind", "status", "run_id"):
        value = body.get(key)
        if value is not None and not (isinstance(value, str) and len(value) <= MAX_TEXT) \
                and not (isinstance(value, int) and not isinstance(value, bool)
                         and abs(value) <= MAX_VALUE):
            raise _Bad(f"{key}: expected a text of at most {MAX_TEXT} characters, got "
                       f"{_show(value)}")
    for key, fields in (("commanded", ("dx_mm", "dy_mm", "dphi_deg")),
                        ("error", ("x_mm", "y_mm", "phi_deg")),
                        ("error_at_look", ("x_mm", "y_mm", "phi_deg"))):
        value = body.get(key)
        if value is None or value == {}:
            continue
        if not isinstance(value, dict):
            raise _Bad(f"{key}: expected an object with {', '.join(fields)}, got "
                       f"{_show(value)}")
        for field in fields:
            _number(value.get(field), f"{key}.{field}", MAX_VALUE)
    overlay = body.get("overlay")
    if overlay is not None:
        if not isinstance(overlay, dict):
            raise _Bad(f"overlay: expected an object, got {_show(overlay)}")
        _points(overlay.get("centre_px"), "overlay.centre_px", 1)
        _points(overlay.get("taught_px"), "overlay.taught_px", 1)
        _points(overlay.get("arrow_px"), "overlay.arrow_px", 2, list_of=True)
        gabor = overlay.get("gabor_px")
        if gabor is not None and not (isinstance(gabor, list) and len(gabor) <= 1024):
            raise _Bad(f"overlay.gabor_px: expected a list of points, got {_show(gabor)}")
        for i, point in enumerate(gabor or ()):
            _points(point, f"overlay.gabor_px[{i}]", 1)
        box = overlay.get("box_px")
        if box is not None:
            if not (isinstance(box, list) and len(box) == 4):
                raise _Bad(f"overlay.box_px: expected [u0, v0, u1, v1], got {_show(box)}")
            for i, value in enumerate(box):
                _number(value, f"overlay.box_px[{i}]", MAX_COORD_PX)
        _number(overlay.get("roi_px"), "overlay.roi_px", MAX_COORD_PX, optional=True)
    return body


def _points(value: Any, key: str, count: int, list_of: bool = False) -> None:
    """``value`` is None, a point [u, v] (``count`` 1) or ``count`` points (``list_of``)."""
    if value is None:
        return
    points = value if list_of else [value]
    if not (isinstance(points, list) and len(points) == count):
        raise _Bad(f"{key}: expected {count} points, got {_show(value)}")
    for point in points:
        if not (isinstance(point, list) and len(point) == 2):
            raise _Bad(f"{key}: expected {_POINT}, got {_show(point)}")
        for value_ in point:
            _number(value_, key, MAX_COORD_PX)


def _number(value: Any, key: str, limit: float, optional: bool = False) -> None:
    """``value`` is a finite number within +-``limit`` (or None when ``optional``)."""
    if value is None and optional:
        return
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and (
        abs(value) <= limit if isinstance(value, int) else math.isfinite(value)
        and abs(value) <= limit)
    if not ok:
        raise _Bad(f"{key}: expected a number within +-{limit:g}, got {_show(value)}")


def _type(value: Any) -> str:
    return {dict: "an object", list: "a list", str: "a text", bool: "a boolean",
            type(None): "null"}.get(type(value), "a number")


def _show(value: Any) -> str:
    """``value`` as JSON, cut to a few dozen characters (never a 10**400 spelled out)."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) > 10 ** 30:
        return "a number of more than 30 digits"
    text = json.dumps(value)
    return text if len(text) <= 40 else text[:37] + "..."


def render(look: Look, scale: int = 4) -> np.ndarray:
    """The look's frame with its overlay and texts (BGR, ``scale`` times the camera size)."""
    return draw(look.image, look.overlay, look.texts(), scale)


def check_output(out: str | Path) -> Path:
    """``out`` as a Path whose folder exists (replay creates none: a mistyped path is an error,
    not a new folder).

    Raises:
        RecordingError: the folder does not exist or is not a folder.
    """
    out = Path(out)
    if not out.parent.is_dir():
        raise RecordingError(f"{out}: no such folder {out.parent}")
    return out


def write_video(looks: list[Look], out: str | Path, fps: float = 2.0, scale: int = 4,
                hold: int = 1) -> Path:
    """Write the looks as an MP4 video (``hold`` video frames per look), atomically: under a
    temporary name beside ``out``, checked to hold every frame, synced and renamed over it.

    Raises:
        RecordingError: the folder does not exist, OpenCV cannot open a video writer there, or
            the written video is incomplete (a full disk); no file is left at ``out`` or
            under the temporary name.
    """
    out = check_output(out)
    first = render(looks[0], scale)
    h, w = first.shape[:2]
    # the container is chosen from the extension, so the temporary name keeps it
    tmp = out.parent / f".{out.stem}.{secrets.token_hex(4)}.tmp{out.suffix}"
    try:
        writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*"mp4v"), fps, (w, h))
        if not writer.isOpened():
            raise RecordingError(f"{out}: cannot write an MP4 video there")
        try:
            for i, look in enumerate(looks):
                frame = first if i == 0 else render(look, scale)
                for _ in range(hold):
                    writer.write(frame)
        finally:
            writer.release()
        _check_video(tmp, out, len(looks) * hold)
        os.replace(tmp, out)
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
    return out


def _check_video(tmp: Path, out: Path, frames: int) -> None:
    """Sync the written video and check its container counts ``frames`` frames (OpenCV's
    writer reports no write error: a full disk shows as a file without its index)."""
    try:
        fd = os.open(tmp, os.O_RDONLY | os.O_CLOEXEC)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
    except OSError as exc:
        raise RecordingError(f"{out}: the video could not be written: "
                             f"{exc.strerror or exc}") from None
    capture = cv2.VideoCapture(str(tmp))
    try:
        counted = int(capture.get(cv2.CAP_PROP_FRAME_COUNT)) if capture.isOpened() else 0
    finally:
        capture.release()
    if counted != frames:
        raise RecordingError(f"{out}: the video could not be written completely ({counted} of "
                             f"{frames} frames; is the disk full?)")


def write_sheet(looks: list[Look], out: str | Path, columns: int = 4, scale: int = 2) -> Path:
    """Write a contact sheet: one tile per look, left to right, top to bottom (PNG), atomically.

    Raises:
        RecordingError: the folder does not exist or the image cannot be encoded.
        OSError: it cannot be written (a full disk); no file is left behind.
    """
    out = check_output(out)
    tiles = [render(look, scale) for look in looks]
    h, w = tiles[0].shape[:2]
    columns = max(1, min(columns, len(tiles)))
    rows = math.ceil(len(tiles) / columns)
    gap = 4
    sheet = np.full((rows * (h + gap) + gap, columns * (w + gap) + gap, 3), 40, np.uint8)
    for i, tile in enumerate(tiles):
        r, c = divmod(i, columns)
        y, x = gap + r * (h + gap), gap + c * (w + gap)
        sheet[y:y + h, x:x + w] = tile
    try:
        ok, encoded = cv2.imencode(out.suffix or ".png", sheet)
    except cv2.error:
        ok = False
    if not ok:
        raise RecordingError(f"{out}: cannot encode the contact sheet as {out.suffix or 'PNG'}")
    atomic_write_bytes(out, encoded.tobytes())
    return out
