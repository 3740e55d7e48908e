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
