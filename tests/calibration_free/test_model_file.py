"""The finepos model file: refuses corrupt, truncated, foreign and other-version files."""

from __future__ import annotations

import numpy as np
import pytest

from calibration_free.errors import BundleError
from calibration_free.model_file import read_model, write_model

ARRAYS = {"w": np.arange(6.0).reshape(2, 3), "n": np.array([1, 2, 3], dtype=np.int64)}


@pytest.fixture()
def good(tmp_path):
    path = tmp_path / "m.pca"
    write_model(path, "pca", 1, {"object_kind": "cube", "x": [1.5, 2.0]}, ARRAYS)
    return path


def test_round_trip(good):
    info, arrays = read_model(good, "pca", 1)
    assert info["object_kind"] == "cube" and info["x"] == [1.5, 2.0] and info["kind"] == "pca"
    for k, v in ARRAYS.items():
        np.testing.assert_array_equal(arrays[k], v)
    assert [p.name for p in good.parent.iterdir()] == ["m.pca"]  # no temporary left


def test_refusals(good, tmp_path):
    data = good.read_bytes()
    cases = {"missing": None, "empty": b"", "truncated": data[: len(data) // 2],
             "flipped": data[:-3] + bytes([data[-3] ^ 1]) + data[-2:],
             "garbage": b"\x10\x00\x00\x00\x00\x00\x00\x00not json at all!"}
    for name, content in cases.items():
        path = tmp_path / name
        if content is not None:
            path.write_bytes(content)
        with pytest.raises(BundleError):
            read_model(path, "pca", 1)
    text = tmp_path / "notes.txt"
    text.write_bytes(b"garbage, not a model\n")
    with pytest.raises(BundleError, match="not a pca model file .no model header"):
        read_model(text, "pca", 1)
    with pytest.raises(BundleError, match="truncated"):
        read_model(tmp_path / "truncated", "pca", 1)
    with pytest.raises(BundleError, match="'pca' model, not a 'hough'"):
        read_model(good, "hough", 1)
    with pytest.raises(BundleError, match="version 1 is not supported"):
        read_model(good, "pca", 2)


def test_unserialisable_metadata_is_refused(tmp_path):
    with pytest.raises(BundleError, match="serialise"):
        write_model(tmp_path / "x", "pca", 1, {"bad": float("nan")}, ARRAYS)
    assert not list(tmp_path.iterdir())


def test_edited_header_fails_the_checksum(good):
    data = good.read_bytes()
    assert data.count(b"cube") == 1
    good.write_bytes(data.replace(b"cube", b"cubo"))  # still valid JSON, same length
    with pytest.raises(BundleError, match="checksum"):
        read_model(good, "pca", 1)


# -- hardening (issue 15): hostile model files give one line naming the file and the problem -----
def _one_line_error(path) -> str:
    import pytest as _pytest

    from calibration_free.errors import BundleError
    from calibration_free.model_file import read_model

    with _pytest.raises(BundleError) as refused:
        read_model(path, "gabor", 1)
    message = str(refused.value)
    assert "\n" not in message and str(path) in message and len(message) < 400, message
    return message


def test_model_from_a_fifo_or_dev_zero_is_refused_at_once(tmp_path):
    import os

    fifo = tmp_path / "fifo.fpm"
    os.mkfifo(fifo)
    assert "FIFO" in _one_line_error(fifo)
    zero = tmp_path / "zero.fpm"
    zero.symlink_to("/dev/zero")
    assert "character device" in _one_line_error(zero)


def test_every_flipped_header_byte_gives_one_line_without_the_header(tmp_path):
    import numpy as np

    from calibration_free.model_file import write_model

    path = tmp_path / "m.fpm"
    write_model(path, "gabor", 1, {"object_kind": "cube", "secret": "HEADERTEXT" * 5},
                {"w": np.arange(6.0)})
    data = path.read_bytes()
    header_len = int.from_bytes(data[:8], "little")
    bad = tmp_path / "bad.fpm"
    for offset in range(0, 8 + header_len, 7):
        flipped = bytearray(data)
        flipped[offset] ^= 0x80
        bad.write_bytes(bytes(flipped))
        message = _one_line_error(bad)  # anything but a BundleError fails here
        assert "HEADERTEXT" not in message, (offset, message)
