"""Split a terminal byte stream into input lines the way the VAL monitor reads them.

``\\r``, ``\\n``, ``\\r\\n`` and ``\\n\\r`` each end one line (public PUMA drivers send ``\\r`` or
``\\n\\r``), so ``"x\\n\\r\\n\\r"`` is the line ``x`` followed by one empty line. A pair split
across two reads still counts as one line ending.
"""

from __future__ import annotations

_ENDINGS = frozenset(b"\r\n")


class LineAssembler:
    """Collects bytes; ``feed`` returns the lines completed by them (latin-1 decoded)."""

    def __init__(self) -> None:
        self._buffer = bytearray()
        self._last_ending: int | None = None  # the ending byte that closed the previous line

    def feed(self, data: bytes) -> list[str]:
        lines = []
        for byte in data:
            if byte in _ENDINGS:
                if self._last_ending is not None and byte != self._last_ending:
                    self._last_ending = None  # second half of a \r\n or \n\r pair
                    continue
                lines.append(self._buffer.decode("latin-1"))
                self._buffer.clear()
                self._last_ending = byte
            else:
                self._buffer.append(byte)
                self._last_ending = None
        return lines
