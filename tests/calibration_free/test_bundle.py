"""Model bundle: round trip, atomic save, refusal of corrupt, truncated, foreign bundles."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from calibration_free.axis import AxisMap
from calibration_free.bundle import FORMAT_VERSION, KIND, ModelBundle
from calibration_free.ends import EndMap
from calibration_free.errors import BundleError
from calibration_free.gabor import GaborConfig
from calibration_free.heading_zero import HeadingZero
from calibration_free.model_file import pack_model
from calibration_free.perception import Perception
from calibration_free.synthetic import render
from drivers.core.errors import ConfigError
from drivers.core.typed_config import to_mapping

from .conftest import KAPPA, NOMINAL_POSE


def test_round_trip_keeps_everything(bundle, cell, tmp_path):
    path = tmp_path / "cube.bundle"
    bundle.save(path)
    again = ModelBundle.load(path, expect_object="cube")
    assert [p.name for p in tmp_path.iterdir()] == ["cube.bundle"]
    for f in dataclasses.fields(ModelBundle):
        if f.name not in ("nn1", "nn1_rot", "nn1_near", "nn2"):
            assert getattr(again, f.name) == getattr(bundle, f.name), f.name
    assert again.kappa == KAPPA and again.nominal_pose == NOMINAL_POSE
    assert again.format_version == FORMAT_VERSION
    assert again.pose.as_dict() == NOMINAL_POSE
    for name in ("nn1", "nn1_rot", "nn1_near", "nn2"):
        a, b = getattr(bundle, name).to_arrays(name), getattr(again, name).to_arrays(name)
        assert a.keys() == b.keys()
        for k in a:
            np.testing.assert_array_equal(a[k], b[k])
    frame = render(cell, np.array([2.0, -3.0, 12.0]), np.random.default_rng(0))
    p, q = Perception(bundle).perceive(frame), Perception(again).perceive(frame)
    assert (p.nn1_mm, p.full_mm, p.nn2_sc, p.dphi_deg) == (q.nn1_mm, q.full_mm, q.nn2_sc,
                                                            q.dphi_deg)


def info_and_tensors(bundle: ModelBundle) -> tuple[dict, dict]:
    return bundle.to_info(), bundle.arrays()


def pack(info: dict, tensors: dict, version: int = FORMAT_VERSION) -> bytes:
    return pack_model(KIND, version, info, tensors)


def bad_files(bundle: ModelBundle, good: bytes) -> dict[str, bytes]:
    header_len = int.from_bytes(good[:8], "little")
    in_data = bytearray(good)
    in_data[-5] ^= 0x10                       # a weight changes: only the digest sees it
    in_header = bytearray(good)
    marker = b'kappa\\": '                   # the info JSON sits escaped in the header
    at = good.index(marker, 8) + len(marker)
    assert good[at:at + 1] == b"4"
    in_header[at] = ord("3")                  # kappa 4 -> 3: still valid JSON
    info, tensors = info_and_tensors(bundle)
    no_digest = pack(info, tensors).replace(b'"sha256"', b'"sha999"')
    return {
        "flipped_weight": bytes(in_data),
        "edited_header": bytes(in_header),
        "no_digest": no_digest,
        "truncated_half": good[: len(good) // 2],
        "truncated_tail": good[:-3],
        "header_only": good[: 8 + header_len],
        "tiny": good[:5],
        "empty": b"",
        "garbage": b"\x00" * 64,
    }


def test_corrupt_or_truncated_bundles_are_refused_and_nothing_changes(bundle, tmp_path):
    good_path = tmp_path / "cube.bundle"
    bundle.save(good_path)
    good = good_path.read_bytes()
    for name, data in bad_files(bundle, good).items():
        path = tmp_path / f"{name}.bundle"
        path.write_bytes(data)
        with pytest.raises(BundleError, match=path.name):
            ModelBundle.load(path)
        assert path.read_bytes() == data, name
    assert good_path.read_bytes() == good
    assert ModelBundle.load(good_path).object_kind == "cube"


def version_4_info(bundle: ModelBundle) -> dict:
    """The JSON of a version-4 bundle as finepos wrote it when the bundle kept its front end
    as flat fields: every key spelled out here, not taken from the code under test."""
    f = bundle.front
    return {
        "object_kind": "cube",
        "kappa": KAPPA,
        "nominal_pose": dict(NOMINAL_POSE),
        "frame_px": {"height": 144, "width": 192},
        "intensity": {"mean": f.intensity.mean, "std": f.intensity.std},
        "localisation": {"threshold": f.threshold, "polarity": "bright",
                         "expected_area_px": f.expected_area_px,
                         "area_tolerance": f.area_tolerance,
                         "max_elongation": f.max_elongation, "channel": "max",
                         "nominal_uv_px": [f.nominal_uv_px[0], f.nominal_uv_px[1]]},
        "gabor": to_mapping(bundle.gabor),
        "training": {"seed": 0},
    }


def test_a_file_in_the_version_4_layout_loads_and_is_still_written(bundle, cell, tmp_path):
    path = tmp_path / "v4.bundle"
    arrays = {k: v for k, v in bundle.arrays().items() if not k.startswith("nn1_near.")}
    path.write_bytes(pack(version_4_info(bundle), arrays, version=4))
    old = ModelBundle.load(path, expect_object="cube")
    # a version-4 file has no learned colour nor taught area and outline: the same front end
    # without the colour check, the hidden-part check and the outline fit
    assert old.front.chroma is None and bundle.front.chroma is not None
    assert old.front.taught_area_px is None and bundle.front.taught_area_px is not None
    assert old.front == dataclasses.replace(bundle.front, chroma=None, chroma_tolerance=0.0,
                                            taught_area_px=None, taught_outline_px=None,
                                            turned_outlines_px=())
    assert old.training == {"seed": 0}
    # no near net: every look's translation is nn1_rot's, as version 4 perceived
    assert old.near_mm == 0.0 and old.format_version == 4
    frame = render(cell, np.array([-1.5, 2.0, 8.0]), np.random.default_rng(2))
    p, q = Perception(bundle).perceive(frame), Perception(old).perceive(frame)
    assert p.near and not q.near and q.full_mm == q.rot_mm
    assert (p.nn1_mm, p.rot_mm, p.nn2_sc, p.dphi_deg) == (q.nn1_mm, q.rot_mm, q.nn2_sc,
                                                           q.dphi_deg)
    # saving writes the same layout, plus the part's colour and the near net's range
    written = bundle.to_info()
    expected = version_4_info(bundle)
    assert sorted(written) == sorted([*expected, "near_mm", "axis", "heading_zero"])
    assert written["localisation"] == {**expected["localisation"],
                                       "chroma": list(bundle.front.chroma),
                                       "chroma_tolerance": bundle.front.chroma_tolerance,
                                       "feature_floor": bundle.front.feature_floor,
                                       "feature_ceiling": bundle.front.feature_ceiling,
                                       "taught_area_px": bundle.front.taught_area_px,
                                       "taught_outline_px": [
                                           list(p) for p in bundle.front.taught_outline_px],
                                       "turned_outlines_px": [
                                           [t, [list(p) for p in o]]
                                           for t, o in bundle.front.turned_outlines_px],
                                       "edge_gamma": bundle.front.edge_gamma,
                                       "edge_fill_holes": bundle.front.edge_fill_holes}
    assert written["frame_px"] == expected["frame_px"]
    assert written["intensity"] == expected["intensity"]


def test_checksum_catches_a_single_changed_weight(bundle, tmp_path):
    path = tmp_path / "flip.bundle"
    path.write_bytes(bad_files(bundle, pack(*info_and_tensors(bundle)))["flipped_weight"])
    with pytest.raises(BundleError, match="checksum"):
        ModelBundle.load(path)


def test_wrong_version_is_refused(bundle, tmp_path):
    path = tmp_path / "future.bundle"
    path.write_bytes(pack(*info_and_tensors(bundle), version=FORMAT_VERSION + 1))
    with pytest.raises(BundleError, match=f"version {FORMAT_VERSION + 1} is not supported"):
        ModelBundle.load(path)


def test_wrong_object_is_refused(bundle, tmp_path):
    path = tmp_path / "cube.bundle"
    bundle.save(path)
    with pytest.raises(BundleError, match="taught on object 'cube', not 'screw'"):
        ModelBundle.load(path, expect_object="screw")


def test_not_a_bundle_and_missing_file_are_refused(bundle, tmp_path):
    info, tensors = info_and_tensors(bundle)
    info["format"] = "something-else"
    path = tmp_path / "other.bundle"
    path.write_bytes(pack(info, tensors))
    with pytest.raises(BundleError, match="not a finepos model file"):
        ModelBundle.load(path)
    with pytest.raises(BundleError, match="cannot read"):
        ModelBundle.load(tmp_path / "missing.bundle")


def test_another_systems_model_is_refused(bundle, tmp_path):
    path = tmp_path / "pca.model"
    path.write_bytes(pack_model("pca", 1, {}, bundle.arrays()))
    with pytest.raises(BundleError, match="a 'pca' model, not a 'gabor' model"):
        ModelBundle.load(path)


def test_inconsistent_contents_are_refused(bundle, tmp_path):
    info, tensors = info_and_tensors(bundle)
    del tensors["nn2.w1"]
    path = tmp_path / "cut.bundle"
    path.write_bytes(pack(info, tensors))
    with pytest.raises(BundleError, match="inconsistent"):
        ModelBundle.load(path)
    with pytest.raises(BundleError, match="nn2: must map 27 features"):
        dataclasses.replace(bundle, gabor=GaborConfig(orientations_deg=(0.0, 60.0, 120.0)))
    with pytest.raises(BundleError, match="nominal_pose"):
        dataclasses.replace(bundle, nominal_pose={"x_mm": 1.0})


def test_failed_save_keeps_the_old_file(bundle, tmp_path):
    path = tmp_path / "cube.bundle"
    bundle.save(path)
    good = path.read_bytes()
    broken = dataclasses.replace(bundle, training={"bad": float("nan")})
    with pytest.raises(BundleError, match="serialise"):
        broken.save(path)
    assert path.read_bytes() == good
    assert json.loads(json.dumps(bundle.training))["nn1"]["layers"] == [2, 3, 2]


def an_axis_map() -> AxisMap:
    """An axis map for a part of kappa 1, every field spelled out."""
    return AxisMap(kappa=1, axis0_deg=-89.9, elongation=1.7, uv0_px=(95.7, 66.7),
                   whole=(0.09, -6.5, -0.04, -7.8, -0.02, 0.54, -0.02, 0.51, 0.01, 0.11, 0.006),
                   near=(0.72, -0.008, 0.28, -0.05), near_range_deg=33.4, whole_rms_deg=0.72,
                   near_rms_deg=0.33, samples=67)


def test_an_axis_map_round_trips_and_must_match_the_part(bundle, tmp_path):
    screw = dataclasses.replace(bundle, object_kind="screw", kappa=1, axis=an_axis_map())
    path = tmp_path / "screw.bundle"
    screw.save(path)
    again = ModelBundle.load(path, expect_object="screw")
    assert again.axis == screw.axis and again.to_info()["axis"] == screw.to_info()["axis"]
    with pytest.raises(BundleError, match="axis: must be an axis map of the part's kappa 4"):
        dataclasses.replace(bundle, axis=an_axis_map())
    info, tensors = info_and_tensors(screw)
    info["axis"] = {**info["axis"], "near": info["axis"]["near"][:2]}
    path.write_bytes(pack(info, tensors))
    with pytest.raises(BundleError, match="axis: whole needs 11 numbers, near 4"):
        ModelBundle.load(path)


def test_a_version_5_file_has_no_axis_map(bundle, tmp_path):
    screw = dataclasses.replace(bundle, object_kind="screw", kappa=1, axis=an_axis_map())
    info, tensors = info_and_tensors(screw)
    del info["axis"]
    path = tmp_path / "v5.bundle"
    path.write_bytes(pack(info, tensors, version=5))
    old = ModelBundle.load(path, expect_object="screw")
    assert old.axis is None and old.format_version == 5


def test_a_bars_end_map_round_trips_and_a_version_6_file_has_none(bundle, tmp_path):
    ends = EndMap(direction=(0.0, -1.0), low=tuple(np.arange(10) / 10.0),
                  high=tuple(-np.arange(10) / 10.0), length_px=73.4, rms_px=(0.3, 0.4))
    ledge = dataclasses.replace(
        bundle, object_kind="ledge", kappa=2,
        axis=dataclasses.replace(an_axis_map(), kappa=2, ends=ends))
    path = tmp_path / "ledge.bundle"
    ledge.save(path)
    again = ModelBundle.load(path, expect_object="ledge")
    assert again.axis.ends == ends
    info, tensors = info_and_tensors(ledge)
    info["axis"] = {**info["axis"], "ends": {**info["axis"]["ends"], "low": [1.0, 2.0]}}
    path.write_bytes(pack(info, tensors))
    with pytest.raises(BundleError, match="axis.ends: needs a unit direction, 10 coefficients"):
        ModelBundle.load(path)
    info, tensors = info_and_tensors(ledge)
    del info["axis"]["ends"]
    path.write_bytes(pack(info, tensors, version=6))
    old = ModelBundle.load(path, expect_object="ledge")
    assert old.format_version == 6 and old.axis is not None and old.axis.ends is None


def test_a_version_7_files_axis_map_reads_the_features_silhouette(bundle, tmp_path):
    screw = dataclasses.replace(bundle, object_kind="screw", kappa=1,
                                axis=dataclasses.replace(an_axis_map(), silhouette="coverage"))
    path = tmp_path / "screw.bundle"
    screw.save(path)
    assert ModelBundle.load(path).axis.silhouette == "coverage"
    info, tensors = info_and_tensors(screw)
    del info["axis"]["silhouette"]
    path.write_bytes(pack(info, tensors, version=7))
    old = ModelBundle.load(path, expect_object="screw")
    assert old.format_version == 7 and old.axis.silhouette == "features"


def test_a_version_8_file_reads_the_rims_of_the_parts_holes(bundle, tmp_path):
    holed = dataclasses.replace(bundle, front=dataclasses.replace(
        bundle.front, edge_gamma=2.2, edge_fill_holes=True))
    path = tmp_path / "ledge.bundle"
    holed.save(path)
    assert ModelBundle.load(path).front.edge.fill_holes
    info, tensors = info_and_tensors(holed)
    del info["localisation"]["edge_fill_holes"]
    path.write_bytes(pack(info, tensors, version=8))
    old = ModelBundle.load(path)
    assert old.format_version == 8 and old.front.edge_gamma == 2.2
    assert not old.front.edge.fill_holes


def test_a_version_9_file_has_no_zero_by_heading_and_version_10_keeps_it(bundle, tmp_path):
    table = HeadingZero((0.0, 45.0), (0.3, -0.4))
    path = tmp_path / "cube.bundle"
    dataclasses.replace(bundle, heading_zero=table).save(path)
    assert ModelBundle.load(path).heading_zero == table
    info, tensors = info_and_tensors(bundle)
    del info["heading_zero"]
    path.write_bytes(pack(info, tensors, version=9))
    old = ModelBundle.load(path)
    assert old.format_version == 9 and old.heading_zero is None


def test_version_11_keeps_the_translation_by_heading_and_a_version_10_file_loads(bundle,
                                                                                  tmp_path):
    table = HeadingZero((0.0, 45.0), (0.3, -0.4), (0.0, 0.05), (0.0, -0.02))
    path = tmp_path / "cube.bundle"
    dataclasses.replace(bundle, heading_zero=table).save(path)
    assert ModelBundle.load(path).heading_zero == table
    info, tensors = info_and_tensors(dataclasses.replace(
        bundle, heading_zero=HeadingZero((0.0, 45.0), (0.3, -0.4))))
    path.write_bytes(pack(info, tensors, version=10))
    old = ModelBundle.load(path)
    assert old.format_version == 10 and old.heading_zero == HeadingZero((0.0, 45.0), (0.3, -0.4))
    assert not old.heading_zero.has_translation


def test_the_taught_area_is_learned_and_checked(bundle, cell, tmp_path):
    """The part's blob area at the taught pose (the hidden-part check's reference): the
    taught-pose frames' mean, which a frame there reads back."""
    front = bundle.front
    frame = render(cell, np.array([0.0, 0.0, 0.0]), np.random.default_rng(5))
    _, loc = front.locate(frame)
    assert loc.ok and front.seen_share(loc.area_px) == pytest.approx(1.0, abs=0.03)
    # what a card hides shows in the share
    assert front.seen_share(0.7 * loc.area_px) == pytest.approx(0.7, abs=0.03)
    for bad in (0.0, -5.0, float("nan"), True, "1600"):
        with pytest.raises(ConfigError, match="taught_area_px"):
            dataclasses.replace(front, taught_area_px=bad)
    # in a model file: refused with the file named, as any bad field
    info, tensors = info_and_tensors(bundle)
    info["localisation"]["taught_area_px"] = -1.0
    path = tmp_path / "bad-area.bundle"
    path.write_bytes(pack(info, tensors))
    with pytest.raises(BundleError, match="bad-area.bundle.*taught_area_px"):
        ModelBundle.load(path)
