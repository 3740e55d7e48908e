"""Datasets: one-file round trip, grids and random offsets, refusal of bad files."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest

from calibration_free.dataset import (
    Dataset,
    grid_offsets,
    random_offsets,
    staggered_grid_offsets,
)
from calibration_free.errors import DatasetError


def sample_set(n: int = 5) -> Dataset:
    rng = np.random.default_rng(0)
    return Dataset(labels=rng.normal(size=(n, 3)),
                   images=rng.integers(0, 256, (n, 6, 8, 3), dtype=np.uint8),
                   features=rng.normal(size=(n, 36)).astype(np.float32),
                   samples=[{"index": i, "pose": {"x_mm": float(i)}} for i in range(n)],
                   metadata={"object": "cube", "a_mm": 25.0, "kappa": 4})


def test_round_trip_keeps_everything(tmp_path):
    data = sample_set()
    path = tmp_path / "set.npz"
    data.save(path)
    again = Dataset.load(path)
    np.testing.assert_array_equal(again.labels, data.labels)
    np.testing.assert_array_equal(again.images, data.images)
    np.testing.assert_array_equal(again.features, data.features)
    assert again.samples == data.samples and again.metadata == data.metadata
    assert len(again) == 5
    assert [p.name for p in tmp_path.iterdir()] == ["set.npz"]


def test_round_trip_of_labels_only(tmp_path):
    data = Dataset(grid_offsets(5.0, 45.0))
    data.save(tmp_path / "labels.npz")
    again = Dataset.load(tmp_path / "labels.npz")
    assert again.images is None and again.features is None and again.samples is None
    np.testing.assert_array_equal(again.labels, data.labels)


def test_grid_is_the_papers_3x3x7():
    labels = grid_offsets(25.0, 45.0)
    assert labels.shape == (63, 3)
    assert sorted(set(labels[:, 0])) == [-25.0, 0.0, 25.0]
    assert sorted(set(labels[:, 1])) == [-25.0, 0.0, 25.0]
    np.testing.assert_allclose(sorted(set(labels[:, 2])), np.linspace(-45.0, 45.0, 7))
    np.testing.assert_allclose(labels[:7, 2], np.linspace(-45.0, 45.0, 7))  # dphi fastest
    assert grid_offsets(5.0, 10.0, (1, 2, 1)).tolist() == [[0.0, -5.0, 0.0], [0.0, 5.0, 0.0]]
    with pytest.raises(DatasetError, match="grid"):
        grid_offsets(-1.0, 10.0)


@pytest.mark.parametrize("kappa", [1, 2, 4, 6])
def test_staggered_grid_shows_63_distinct_rotations_over_the_period(kappa):
    b = 180.0 / kappa
    labels = staggered_grid_offsets(5.0, b)
    plain = grid_offsets(5.0, b)
    assert labels.shape == (63, 3)
    np.testing.assert_array_equal(labels[:, :2], plain[:, :2])  # the same 9 positions
    phi = np.sort(labels[:, 2])
    # 63 distinct rotations evenly 2b/63 apart, within [-b, b), never both ends of the period
    np.testing.assert_allclose(np.diff(phi), 2.0 * b / 63.0, rtol=1e-9)
    assert -b < phi[0] and phi[-1] < b
    assert phi[0] + 2.0 * b - phi[-1] == pytest.approx(2.0 * b / 63.0)  # across the wrap too
    # the plain grid has only 6 distinct views of the period (its two ends are one view)
    views = {round(float(v) % (2.0 * b), 6) for v in plain[:, 2]}
    assert len(views) == 6
    # every position keeps 7 rotations, evenly spaced, shifted differently at each position
    per_position = labels[:, 2].reshape(9, 7)
    np.testing.assert_allclose(np.diff(per_position, axis=1), 2.0 * b / 7.0)
    assert len({round(float(r[0]), 6) for r in per_position}) == 9
    # neighbouring positions do not get neighbouring shifts
    assert np.abs(np.diff(per_position[:, 0])).min() > 2.0 * b / 63.0 * 1.5


def test_staggered_grid_edge_cases():
    np.testing.assert_array_equal(staggered_grid_offsets(5.0, 45.0, (3, 3, 1)),
                                  grid_offsets(5.0, 45.0, (3, 3, 1)))
    np.testing.assert_array_equal(staggered_grid_offsets(5.0, 0.0), grid_offsets(5.0, 0.0))
    one = staggered_grid_offsets(0.0, 90.0, (1, 1, 4))
    np.testing.assert_allclose(one[:, 2], [-67.5, -22.5, 22.5, 67.5])
    with pytest.raises(DatasetError, match="grid"):
        staggered_grid_offsets(5.0, -1.0)


def test_random_offsets_are_in_range_and_seeded():
    a = random_offsets(np.random.default_rng(3), 500, 5.0, 45.0)
    b = random_offsets(np.random.default_rng(3), 500, 5.0, 45.0)
    np.testing.assert_array_equal(a, b)
    assert a.shape == (500, 3)
    assert np.abs(a[:, :2]).max() <= 5.0 and np.abs(a[:, 2]).max() <= 45.0
    assert np.abs(a[:, 2]).max() > 40.0
    with pytest.raises(DatasetError, match="random offsets"):
        random_offsets(np.random.default_rng(3), 0, 5.0, 45.0)


def test_inconsistent_contents_are_refused():
    with pytest.raises(DatasetError, match="labels"):
        Dataset(np.zeros((4, 2)))
    with pytest.raises(DatasetError, match="images"):
        Dataset(np.zeros((4, 3)), images=np.zeros((3, 6, 8, 3), np.uint8))
    with pytest.raises(DatasetError, match="images"):
        Dataset(np.zeros((4, 3)), images=np.zeros((4, 6, 8, 3), np.float32))
    with pytest.raises(DatasetError, match="samples"):
        Dataset(np.zeros((4, 3)), samples=[{}])
    with pytest.raises(DatasetError, match="labels"):
        Dataset(np.full((2, 3), np.inf))


def test_unserialisable_metadata_is_refused_and_nothing_written(tmp_path):
    with pytest.raises(DatasetError, match="JSON"):
        Dataset(np.zeros((1, 3)), metadata={"when": object()}).save(tmp_path / "x.npz")
    assert list(tmp_path.iterdir()) == []


def corrupt_files(good: bytes) -> dict[str, bytes]:
    flipped = bytearray(good)
    flipped[len(good) // 2] ^= 0xFF
    pickled = io.BytesIO()
    np.savez(pickled, labels=np.array([{"evil": 1}], dtype=object),
             metadata_json=np.frombuffer(b"{}", np.uint8))
    wrong_version = io.BytesIO()
    meta = json.dumps({"format": "finepos-dataset", "version": 99, "metadata": {}})
    np.savez(wrong_version, labels=np.zeros((1, 3)),
             metadata_json=np.frombuffer(meta.encode(), np.uint8))
    return {"truncated": good[: len(good) // 2], "flipped": bytes(flipped), "empty": b"",
            "garbage": b"not a dataset at all", "pickled": pickled.getvalue(),
            "wrong_version": wrong_version.getvalue()}


def test_corrupt_truncated_pickled_or_foreign_files_are_refused(tmp_path):
    path = tmp_path / "set.npz"
    sample_set().save(path)
    for name, data in corrupt_files(path.read_bytes()).items():
        bad = tmp_path / f"{name}.npz"
        bad.write_bytes(data)
        with pytest.raises(DatasetError, match=bad.name):
            Dataset.load(bad)
    with pytest.raises(DatasetError, match="version 99"):
        Dataset.load(tmp_path / "wrong_version.npz")
    with pytest.raises(DatasetError, match="cannot read"):
        Dataset.load(tmp_path / "missing.npz")


def test_labels_beyond_any_grid_are_refused_at_load(tmp_path):
    """Issue 15: a set with labels of 1e308 is refused with one line, not a traceback at train."""
    import numpy as np
    import pytest as _pytest

    from calibration_free.dataset import Dataset
    from calibration_free.errors import DatasetError

    good = Dataset(np.zeros((2, 3)))
    good.save(tmp_path / "nn1.npz")
    with np.load(tmp_path / "nn1.npz") as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays["labels"] = np.array([[1e308, 0.0, 0.0], [0.0, 0.0, 0.0]])
    np.savez(tmp_path / "bad.npz", **arrays)
    with _pytest.raises(DatasetError, match=r"bad\.npz: labels: dx_mm reaches 1e\+308"):
        Dataset.load(tmp_path / "bad.npz")


def test_an_array_header_claiming_too_much_is_refused_before_allocation(tmp_path):
    """Issue 51: a header claiming 10^8 images gave MemoryError (7.54 TiB)."""
    path = tmp_path / "set.npz"
    sample_set().save(path)
    with np.load(path) as npz:
        arrays = {k: npz[k] for k in npz.files if k != "images"}
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "|u1", "fortran_order": False,
                                                   "shape": (10**8, 480, 640, 3)})
    bad = tmp_path / "huge.npz"
    np.savez(bad, **arrays)
    import zipfile
    with zipfile.ZipFile(bad, "a") as archive:
        archive.writestr("images.npy", header.getvalue() + bytes(64))
    with pytest.raises(DatasetError, match=r"huge\.npz: .*images\.npy: its header claims"):
        Dataset.load(bad)
