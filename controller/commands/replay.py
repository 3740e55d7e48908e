"""Draw a run recording's overlays onto its frames: MP4 video, contact sheet.

Read a recording (finepos position/grasp/evaluate --record) and draw, on every look's hand-
camera frame, the part's centre (red), its blob box (yellow), the ROI (blue), the Gabor filter
centres (green), the taught centre (white cross) and the commanded step's expected image motion
(magenta arrow), with the loop kind, loop count, step and, on the simulated cell, the true error
when the frame was taken. One video frame and one sheet tile per look.

Example: finepos replay run.mcap --out run.mp4 --sheet run.png

The output folders must exist; the files appear complete or not at all. A recording that is not
a regular file, a frame larger than 4096x4096 or a record of the wrong shape is one error line
naming the file and what is wrong (exit status 2).
"""

from __future__ import annotations

import argparse

from controller.commands.common import positive_float
from controller.recording.replay import check_output, read_looks, write_sheet, write_video
from drivers.core.errors import ConfigError
from drivers.core.files import write_json


def run(args) -> int:
    """Read the recording, write the video and/or the sheet, print what was written (JSON)."""
    if args.out is None and args.sheet is None:
        raise ConfigError("replay: give --out FILE.mp4, --sheet FILE.png or both")
    for out in (args.out, args.sheet):  # before the recording is read: no folder is made
        if out is not None:
            check_output(out)
    looks = read_looks(args.recording)
    report = {"recording": args.recording, "looks": len(looks),
              "runs": len({look.record.get("run_id") for look in looks})}
    if args.out is not None:
        report["video"] = str(write_video(looks, args.out, fps=args.fps, scale=args.scale))
    if args.sheet is not None:
        report["sheet"] = str(write_sheet(looks, args.sheet, columns=args.columns))
    write_json(None, report)
    return 0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``finepos replay``."""
    parser.add_argument("recording", metavar="FILE.mcap", help="the recording")
    parser.add_argument("--out", metavar="FILE.mp4", help="write the video here")
    parser.add_argument("--sheet", metavar="FILE.png", help="write the contact sheet here")
    parser.add_argument("--fps", type=positive_float, default=2.0,
                        help="video frames (looks) per second (default 2)")
    parser.add_argument("--scale", type=int, choices=range(1, 9), default=4, metavar="1..8",
                        help="video frame size in camera frames (default 4: 768x576)")
    parser.add_argument("--columns", type=int, choices=range(1, 17), default=4, metavar="1..16",
                        help="contact sheet tiles per row (default 4)")
