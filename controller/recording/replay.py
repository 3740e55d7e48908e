"""Replay a run recording: its looks with their overlays, as a video and as a contact sheet.

``read_looks`` pairs each recorded frame with its iteration record (same log time);
``write_video`` writes one frame per look (MP4, ``mp4v``; ``hold_s`` repeats each so a player
shows it long enough to read); ``write_sheet`` tiles the looks in a grid, in order.
"""

from __future__ import annotations

import base64
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from mcap.exceptions import McapError
from mcap.reader import make_reader

from controller.recording import schemas
from controller.recording.overlay import Overlay, draw, look_texts
from controller.recording.writer import RecordingError


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


def read_looks(path: str | Path) -> list[Look]:
    """The looks of a recording, in log-time order.

    Raises:
        RecordingError: the file is missing, not MCAP, or holds no looks.
    """
    path = Path(path)
    images: dict[int, np.ndarray] = {}
    records: dict[int, dict[str, Any]] = {}
    try:
        with open(path, "rb") as f:
            reader = make_reader(f)
            for _, channel, message in reader.iter_messages(
                    topics=[schemas.IMAGE_TOPIC, schemas.ITERATION_TOPIC]):
                body = json.loads(message.data)
                if channel.topic == schemas.IMAGE_TOPIC:
                    raw = np.frombuffer(base64.b64decode(body["data"]), np.uint8)
                    bgr = cv2.imdecode(raw, cv2.IMREAD_COLOR)
                    if bgr is None:
                        raise RecordingError(f"{path}: a {body.get('format')} frame at "
                                             f"{message.log_time} ns does not decode")
                    images[message.log_time] = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
                else:
                    records[message.log_time] = body
    except FileNotFoundError:
        raise RecordingError(f"{path}: no such recording (record one with "
                             "'finepos position --record FILE.mcap')") from None
    except (McapError, ValueError, KeyError, EOFError) as exc:
        raise RecordingError(f"{path}: not a readable finepos recording ({exc})") from None
    looks = [Look(t, images[t], records[t], Overlay.from_dict(records[t].get("overlay") or {}))
             for t in sorted(images) if t in records]
    if not looks:
        raise RecordingError(f"{path}: the recording holds no looks")
    return looks


def render(look: Look, scale: int = 4) -> np.ndarray:
    """The look's frame with its overlay and texts (BGR, ``scale`` times the camera size)."""
    return draw(look.image, look.overlay, look.texts(), scale)


def write_video(looks: list[Look], out: str | Path, fps: float = 2.0, scale: int = 4,
                hold: int = 1) -> Path:
    """Write the looks as an MP4 video (``hold`` video frames per look).

    Raises:
        RecordingError: OpenCV cannot open a video writer there.
    """
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    first = render(looks[0], scale)
    h, w = first.shape[:2]
    writer = cv2.VideoWriter(str(out), cv2.VideoWriter_fourcc(*"mp4v"), fps, (w, h))
    if not writer.isOpened():
        raise RecordingError(f"{out}: cannot write an MP4 video there")
    try:
        for i, look in enumerate(looks):
            frame = first if i == 0 else render(look, scale)
            for _ in range(hold):
                writer.write(frame)
    finally:
        writer.release()
    return out


def write_sheet(looks: list[Look], out: str | Path, columns: int = 4, scale: int = 2) -> Path:
    """Write a contact sheet: one tile per look, left to right, top to bottom (PNG).

    Raises:
        RecordingError: the image cannot be written there.
    """
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
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
    if not cv2.imwrite(str(out), sheet):
        raise RecordingError(f"{out}: cannot write the contact sheet there")
    return out
