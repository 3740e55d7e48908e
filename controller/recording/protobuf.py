"""The protobuf wire format, read: enough to take a recorded ``foxglove.CompressedImage`` apart.

A recording is input from outside: ``fields`` walks one message's top-level fields with every
length checked against the bytes that are there, and raises ``ValueError`` naming what is wrong
(never reads past the end, never allocates more than the message holds).
"""

from __future__ import annotations

from collections.abc import Iterator

VARINT, I64, LEN, I32 = 0, 1, 2, 5
_MAX_VARINT_BYTES = 10

# foxglove.CompressedImage's field numbers (foxglove/CompressedImage.proto)
IMAGE_TIMESTAMP, IMAGE_DATA, IMAGE_FORMAT, IMAGE_FRAME_ID = 1, 2, 3, 4


def _varint(data: bytes, i: int) -> tuple[int, int]:
    """The varint at ``data[i:]`` and the index after it."""
    value = 0
    for n in range(_MAX_VARINT_BYTES):
        if i + n >= len(data):
            raise ValueError("a varint runs past the end of the message")
        byte = data[i + n]
        value |= (byte & 0x7F) << (7 * n)
        if not byte & 0x80:
            return value, i + n + 1
    raise ValueError("a varint longer than 10 bytes")


def fields(data: bytes) -> Iterator[tuple[int, int, int | bytes]]:
    """(field number, wire type, value) of each top-level field of a message, in order: an int
    for VARINT, I64 and I32 fields, the bytes for LEN fields.

    Raises:
        ValueError: the message is malformed (a truncated field, an unknown wire type).
    """
    i = 0
    while i < len(data):
        key, i = _varint(data, i)
        number, wire = key >> 3, key & 7
        if number == 0:
            raise ValueError("a field numbered 0")
        if wire == VARINT:
            value, i = _varint(data, i)
        elif wire in (I64, I32):
            width = 8 if wire == I64 else 4
            if i + width > len(data):
                raise ValueError(f"field {number} runs past the end of the message")
            value, i = int.from_bytes(data[i:i + width], "little"), i + width
        elif wire == LEN:
            length, i = _varint(data, i)
            if i + length > len(data):
                raise ValueError(f"field {number} claims {length} bytes, past the end of the "
                                 "message")
            value, i = data[i:i + length], i + length
        else:
            raise ValueError(f"field {number} has the unknown wire type {wire}")
        yield number, wire, value


def compressed_image(data: bytes) -> tuple[bytes, str]:
    """The encoded frame and its format (``jpeg``, ``png`` ...) of a ``foxglove.CompressedImage``.

    Raises:
        ValueError: the message is malformed or its format is not UTF-8.
    """
    frame, image_format = b"", ""
    for number, wire, value in fields(data):
        if number == IMAGE_DATA and wire == LEN:
            frame = value
        elif number == IMAGE_FORMAT and wire == LEN:
            try:
                image_format = value.decode("utf-8")
            except UnicodeDecodeError:
                raise ValueError("the format is not UTF-8 text") from None
    return frame, image_format
