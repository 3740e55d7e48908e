"""Parse the monitor's ``where`` table by its labelled lines (pure function).

VAL prints a header ``X Y Z O A T`` and the six values (mm, deg) on the next line; many
controllers add a header ``JT1 JT2 JT3 JT4 JT5 JT6`` and six joint angles (deg). V+ style
controllers print one combined header ``X/JT1 Y/JT2 ... T/JT6`` followed by a Cartesian line and a
joint line. Values are found by these labels, never by position in the text.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass

from drivers.core.errors import ProtocolError
from drivers.core.pose import Pose

_CARTESIAN = ("X", "Y", "Z", "O", "A", "T")
_JOINTS = ("JT1", "JT2", "JT3", "JT4", "JT5", "JT6")
_COMBINED = tuple(f"{c}/{j}" for c, j in zip(_CARTESIAN, _JOINTS, strict=True))
# No PUMA pose or joint value comes near this (mm or deg); beyond it the line is noise.
_MAX_ABS = 1e5
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")


@dataclass(frozen=True)
class WhereReading:
    """The tool pose, and the joint angles in degrees when the controller printed them."""

    pose: Pose
    joints_deg: tuple[float, float, float, float, float, float] | None


def _labels(line: str) -> tuple[str, ...]:
    return tuple(line.upper().split())


def _values(lines: Sequence[str], header_index: int, what: str, offset: int = 1) -> list[float]:
    index = header_index + offset
    if index >= len(lines):
        raise ProtocolError(f"where: no values after the {what} header")
    fields = lines[index].split()
    if len(fields) != 6 or not all(_NUMBER.fullmatch(f) for f in fields):
        raise ProtocolError(f"where: expected six numbers after the {what} header, got "
                            f"{lines[index][:80]!r}")
    values = [float(f) for f in fields]
    if not all(math.isfinite(v) and abs(v) <= _MAX_ABS for v in values):
        raise ProtocolError(f"where: {what} values out of range: {lines[index][:80]!r}")
    return values


def _find(lines: Sequence[str], labels: tuple[str, ...]) -> int | None:
    found = [i for i, line in enumerate(lines) if _labels(line) == labels]
    if len(found) > 1:
        raise ProtocolError(f"where: the header {' '.join(labels)} appears {len(found)} times")
    return found[0] if found else None


def parse_where(lines: Sequence[str]) -> WhereReading:
    """Read pose (and joints) from the output lines of ``where``.

    Args:
        lines: the reply's output lines (empty lines may be present; they are skipped).

    Raises:
        ProtocolError: no ``X Y Z O A T`` (or ``X/JT1 ...``) header, or a header not followed by
            six finite numbers.
    """
    filled = [line for line in lines if line.strip()]
    combined = _find(filled, _COMBINED)
    cartesian = _find(filled, _CARTESIAN)
    if combined is not None and cartesian is None:
        pose = _values(filled, combined, "X/JT1 ... T/JT6")
        joints = _values(filled, combined, "X/JT1 ... T/JT6", offset=2)
        return WhereReading(Pose(*pose), tuple(joints))
    if cartesian is None or combined is not None:
        raise ProtocolError("where: expected one 'X Y Z O A T' header in "
                            f"{' | '.join(filled)[:160]!r}")
    pose = _values(filled, cartesian, "X Y Z O A T")
    header = _find(filled, _JOINTS)
    joints = tuple(_values(filled, header, "JT1 ... JT6")) if header is not None else None
    return WhereReading(Pose(*pose), joints)
