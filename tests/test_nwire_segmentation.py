"""N-wire segmentation: dots and N patterns in B-mode frames, as PLUS's fCal finds them.

Specifications:
- on PLUS's real fCal recording, the points found are PLUS's own (same frames segmented, same
  pixels), and the frames PLUS could not segment are skipped with the reason;
- on a rendered frame with known wire intersections, each is found to < 0.1 px and labelled with
  its wire;
- a frame without the phantom is skipped with a reason, never given guessed points;
- the segmented frames written as PLUS XML read back unchanged (``brachycal nwire segment`` too).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from conftest import reference

from brachycal.cli.main import main
from brachycal.data.formats.metaimage import read_image_sequence, write_image_sequence
from brachycal.data.formats.plus_files import Wire, read_plus_config, read_segmented_frames
from brachycal.data.formats.plus_segmentation import read_segmentation_parameters
from brachycal.data.formats.plus_segmented_xml import write_segmented_frames
from brachycal.errors import InputError
from brachycal.imaging import (
    NWireSegmentationParameters,
    find_dots,
    nwire_geometry,
    segment_frame,
    segment_sequence,
)
from brachycal.imaging.nwire_patterns import NO_LINES, NO_PATTERN, TOO_FEW_DOTS
from brachycal.studies.example_files import render_wire_frame as render

FCAL = "plus_fcal_nwire"
CONFIG = "PlusDeviceSet_fCal_Sim_SpatialCalibration_2.0.xml"
#: PLUS writes its points with 6 significant digits (≤ 0.0005 px at u, v < 1000). Our points are
#: PLUS's to that rounding; 0.01 px leaves room for summation order and still catches any change
#: of method (a different weighting or threshold moves centroids by 0.05 px and more).
SAME_AS_PLUS_PX = 0.01

#: fCal 2.0's three Ns (PLUS's phantom definition), metres in the phantom frame.
FCAL2_PATTERNS = [
    tuple(Wire(name, np.array(front) * 1e-3, np.array(back) * 1e-3) for name, front, back in pattern)
    for pattern in (
        (
            ("7:G1_g1", (30, 0, 20), (30, 40, 20)),
            ("8:L1_h1", (55, 0, 20), (35, 40, 20)),
            ("9:M1_m1", (60, 0, 20), (60, 40, 20)),
        ),
        (
            ("4:G3_g3", (30, 0, 10), (30, 40, 10)),
            ("5:H3_l3", (35, 0, 10), (55, 40, 10)),
            ("6:M3_m3", (60, 0, 10), (60, 40, 10)),
        ),
        (
            ("1:H5_h5", (35, 0, 0), (35, 40, 0)),
            ("2:L5_i5", (55, 0, 0), (40, 40, 0)),
            ("3:M5_m5", (60, 0, 0), (60, 40, 0)),
        ),
    )
]


def fcal2_points(offset_u: float = 0.0, y0_m: float = 0.016) -> dict[str, np.ndarray]:
    """Where fCal 2.0's wires cross the image plane y = ``y0_m`` (across the wires) at 0.078 mm/px.

    The Ns' lines run along u (the first side wires on the right, as PLUS's MF images show them,
    the phantom's x = 30 mm at u = 600.21 + ``offset_u``), one N every 10 mm (128.2 px) down the
    image; sub-pixel positions so that rounding cannot pass. One plane cuts every N: the pattern
    fits the phantom's geometry.
    """
    spacing = 0.078e-3
    points = {}
    for k, pattern in enumerate(FCAL2_PATTERNS):
        v = 150.37 + k * 0.010 / spacing
        for wire in pattern:
            t = (y0_m - wire.front_m[1]) / (wire.back_m[1] - wire.front_m[1])
            along_m = wire.front_m[0] + t * (wire.back_m[0] - wire.front_m[0]) - 0.030
            points[wire.name] = np.array([600.21 + offset_u - along_m / spacing, v + 0.013 * along_m / spacing])
    return points


def test_a_rendered_frame_is_segmented_to_a_tenth_of_a_pixel_with_the_right_labels():
    rng = np.random.default_rng(3)
    truth = fcal2_points()
    frame = render(np.array(list(truth.values())), rng)
    params = NWireSegmentationParameters()
    result = segment_frame(frame, nwire_geometry(FCAL2_PATTERNS), params)
    assert result.reason is None and result.points_px is not None
    assert set(result.points_px) == set(truth)
    errors = [float(np.linalg.norm(result.points_px[name] - uv)) for name, uv in truth.items()]
    # 0.1 px: the goal for sub-pixel centroids. PLUS's centroid (every pixel of the region above
    # 10 % of the peak, weighted by the processed image) takes the noise of the dot's rim in: over
    # 8 seeds the largest error is 0.07 px at this noise (σ 1 grey level on a 200-level dot of
    # σ 3 px), 0.1 px at 1.5 levels, 0.25–0.5 px at 6 levels; noise-free, 0.03 px (grid sampling).
    assert max(errors) < 0.1, errors


def test_the_wall_and_the_speckle_are_not_dots():
    rng = np.random.default_rng(4)
    frame = render(np.array(list(fcal2_points().values())), rng)
    dots = find_dots(frame, NWireSegmentationParameters())
    assert dots.found == 9  # the nine wires; the 700 px wall and the noise are gone


def test_a_frame_without_the_phantom_is_skipped_with_a_reason():
    rng = np.random.default_rng(5)
    geometry = nwire_geometry(FCAL2_PATTERNS)
    params = NWireSegmentationParameters()
    # the threshold is relative to the brightest processed pixel (as in PLUS): in a frame of noise
    # alone, speckle passes it, and the search finds no N among those dots
    empty = segment_frame(render(np.zeros((0, 2)), rng), geometry, params)
    assert empty.points_px is None and empty.reason in (NO_LINES, NO_PATTERN)
    assert segment_frame(np.zeros((616, 820), np.uint8), geometry, params).reason == TOO_FEW_DOTS
    # nine bright dots, but scattered: no three of them make an N
    scattered = rng.uniform([100, 100], [700, 500], size=(9, 2))
    result = segment_frame(render(scattered, rng), geometry, params)
    assert result.points_px is None and result.reason == NO_LINES


def _tracked_fields(count: int) -> list[dict[str, str]]:
    identity = "1 0 0 10 0 1 0 20 0 0 1 30 0 0 0 1"
    return [{"ProbeToTrackerTransform": identity, "ReferenceToTrackerTransform": identity} for _ in range(count)]


def test_a_sequence_is_segmented_frame_by_frame_and_written_as_plus_xml(tmp_path):
    rng = np.random.default_rng(6)
    truths = [fcal2_points(offset_u=du) for du in (0.0, -7.3, 4.1)]
    frames = np.stack([render(np.array(list(t.values())), rng) for t in truths])
    fields = _tracked_fields(3)
    fields[2] = {"ProbeToTrackerTransformStatus": "MISSING", **fields[2]}
    write_image_sequence(tmp_path / "seq.mha", frames, timestamps_s=[1.0, 1.1, 1.2], frame_fields=fields)
    sequence = read_image_sequence(tmp_path / "seq.mha")
    config = read_plus_config(_write_config(tmp_path / "config.xml"))
    result = segment_sequence(sequence, config, NWireSegmentationParameters(), source=tmp_path / "seq.mha")
    # the frame without its probe pose is segmented all the same: the pose is missing, not the points
    assert result.reasons == [None, None, None]
    assert result.found == 3 and result.skipped == {} and result.without_pose == 1
    assert result.frames[2].T_tracker_probe is None and result.frames[2].pose_status == ("MISSING", "OK")
    write_segmented_frames(
        tmp_path / "frames.xml", result.frames[:2], result.frames[2:], calibration_times_s=[1.0, 1.1]
    )
    calibration, validation = read_segmented_frames(tmp_path / "frames.xml")
    assert [f.ok for f in calibration + validation] == [True, True, True]
    # read back: its points, its pose recorded as missing, and not a frame a calibration uses
    assert [f.usable for f in calibration + validation] == [True, True, False]
    assert validation[0].pose_status[0] == "MISSING" and validation[0].T_tracker_probe is None
    for name, uv in result.frames[2].points_px.items():
        np.testing.assert_allclose(validation[0].points_px[name], uv, atol=1e-6)
    for written, read in zip(result.frames[:2], calibration, strict=True):
        for name, uv in written.points_px.items():
            # written with 10 significant digits: 1e-6 px is far below any pixel's meaning
            np.testing.assert_allclose(read.points_px[name], uv, atol=1e-6)
        np.testing.assert_allclose(read.T_tracker_probe, written.T_tracker_probe, atol=1e-12)
        np.testing.assert_allclose(read.T_tracker_probe[:3, 3], [0.010, 0.020, 0.030], atol=1e-12)


def _write_config(path):
    """A device set with fCal 2.0's phantom, its registration and PLUS's default segmentation settings."""
    wires = "\n".join(
        "<Pattern Type='NWire'>"
        + "".join(
            f"<Wire Name='{w.name}' EndPointFront='{' '.join(str(x * 1e3) for x in w.front_m)}' "
            f"EndPointBack='{' '.join(str(x * 1e3) for x in w.back_m)}'/>"
            for w in pattern
        )
        + "</Pattern>"
        for pattern in FCAL2_PATTERNS
    )
    path.write_text(
        "<PlusConfiguration><CoordinateDefinitions>"
        "<Transform From='Phantom' To='Reference' Matrix='1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1'/>"
        "</CoordinateDefinitions><Segmentation ApproximateSpacingMmPerPixel='0.078'/>"
        f"<PhantomDefinition><Geometry>{wires}</Geometry></PhantomDefinition></PlusConfiguration>"
    )
    return path


def test_missing_segmentation_settings_take_plus_defaults(tmp_path):
    """Settings left out take PLUS's defaults; a clip rectangle left out is the whole image, as in PLUS
    (fCal 2.0's rectangle would cut a larger frame without a word)."""
    params = read_segmentation_parameters(_write_config(tmp_path / "config.xml"))
    assert params == replace(NWireSegmentationParameters(), clip_origin_px=None, clip_size_px=None)


def test_a_malformed_setting_is_refused_naming_the_attribute(tmp_path):
    path = _write_config(tmp_path / "config.xml")
    path.write_text(path.read_text().replace("ApproximateSpacingMmPerPixel='0.078'", "ThresholdImagePercent='abc'"))
    with pytest.raises(InputError, match=r"Segmentation/@ThresholdImagePercent: expected 1 finite number, got 'abc'"):
        read_segmentation_parameters(path)


def test_16_bit_frames_are_refused(tmp_path):
    write_image_sequence(tmp_path / "seq.mha", np.zeros((1, 64, 64), np.uint16), frame_fields=_tracked_fields(1))
    config = read_plus_config(_write_config(tmp_path / "config.xml"))
    with pytest.raises(InputError, match="8-bit"):
        segment_sequence(read_image_sequence(tmp_path / "seq.mha"), config, NWireSegmentationParameters(), source="x")


@pytest.mark.parametrize(
    ("sequence", "frames", "which"),
    [
        ("fCal_Test_Validation_3NWires_fCal2.0.igs.mha", (0, 37, 102), 1),
        ("fCal_Test_Calibration_3NWires_fCal2.0.igs.mha", (0, 98, 149, 189), 0),
    ],
)
def test_real_frames_give_plus_points(sequence, frames, which):
    config_path = reference(FCAL, CONFIG)
    plus = read_segmented_frames(reference(FCAL, "fCal_3NWires_segmented_frames.xml"))[which]
    images = read_image_sequence(reference(FCAL, sequence))
    geometry = nwire_geometry(read_plus_config(config_path).patterns)
    params = read_segmentation_parameters(config_path)
    for k in frames:
        result = segment_frame(images.pixels[k], geometry, params)
        assert (result.points_px is not None) == plus[k].ok, f"frame {k}: {result.reason}"
        if not plus[k].ok:  # frames 98 and 149 of the calibration: PLUS finds too few dots too
            assert result.reason == TOO_FEW_DOTS
            continue
        assert set(result.points_px) == set(plus[k].points_px)
        for name, uv in plus[k].points_px.items():
            assert np.linalg.norm(result.points_px[name] - uv) < SAME_AS_PLUS_PX, (k, name)


def test_brachycal_nwire_segment_writes_frames_the_reader_takes(tmp_path, capsys):
    rng = np.random.default_rng(7)
    truths = [fcal2_points(offset_u=du) for du in (0.0, -5.0, 3.0, -9.0)]
    frames = np.stack([render(np.array(list(t.values())), rng) for t in truths])
    write_image_sequence(tmp_path / "cal.mha", frames[:2], frame_fields=_tracked_fields(2))
    write_image_sequence(tmp_path / "val.mha", frames[2:], frame_fields=_tracked_fields(2))
    config = _write_config(tmp_path / "config.xml")
    argv = ["nwire", "segment", str(tmp_path / "cal.mha"), str(tmp_path / "val.mha"), "--config", str(config)]
    assert main([*argv, "--out", str(tmp_path / "frames.xml"), "--quiet"]) == 0
    assert "cal.mha: 2 of 2 frames segmented" in capsys.readouterr().out
    calibration, validation = read_segmented_frames(tmp_path / "frames.xml")
    assert [f.ok for f in calibration + validation] == [True] * 4
    for frame, truth in zip(calibration + validation, truths, strict=True):
        for name, uv in truth.items():
            assert np.linalg.norm(frame.points_px[name] - uv) < 0.1  # the rendered frames' goal, as above


def _mm_text(T: np.ndarray) -> str:
    M = np.array(T, dtype=float)
    M[:3, 3] *= 1e3
    return " ".join(repr(float(x)) for x in M.reshape(-1))


def test_nwire_from_rendered_sequences_matches_nwire_from_their_points(tmp_path):
    """The twin's example frames rendered as images: `brachycal nwire --calibration-sequence …`
    calibrates as `brachycal nwire` on the points themselves, the labels coming from the image
    orientation (the twin's image is PLUS's MF mirrored left to right: UF)."""
    from conftest import ROOT

    from brachycal.calibration.phantom.nwire_file import read_nwire

    config = ROOT / "examples" / "nwire" / "PlusDeviceSet_twin_fCal2.xml"
    calibration, validation = read_segmented_frames(ROOT / "examples" / "nwire" / "twin_segmented_frames.xml")
    calibration, validation = calibration[:15], validation[:8]
    write_segmented_frames(tmp_path / "points.xml", calibration, validation)
    rng = np.random.default_rng(8)
    for name, frames in (("cal.mha", calibration), ("val.mha", validation)):
        # 0.1864 mm/px: a 0.5 mm wire echo is ~3 px across (σ 1.2 px)
        pixels = np.stack([render(np.array(list(f.points_px.values())), rng, sigma_px=1.2) for f in frames])
        fields = [
            {
                "ProbeToTrackerTransform": _mm_text(f.T_tracker_probe),
                "ReferenceToTrackerTransform": _mm_text(f.T_tracker_reference),
            }
            for f in frames
        ]
        write_image_sequence(tmp_path / name, pixels, frame_fields=fields)
    sequences = [
        "--calibration-sequence",
        str(tmp_path / "cal.mha"),
        "--validation-sequence",
        str(tmp_path / "val.mha"),
    ]
    out = tmp_path / "from_images.json"
    assert main(["nwire", str(config), "--out", str(out), "--orientation", "UF", "--quiet", *sequences]) == 0
    assert main(["nwire", str(config), str(tmp_path / "points.xml"), "--out", str(tmp_path / "from_points.json")]) == 0
    from_images, from_points = read_nwire(out), read_nwire(tmp_path / "from_points.json")
    # Rendered dots are found to < 0.1 px (test above), 0.02 mm at 0.19 mm/px; over the middle-wire
    # points (45 here) that moves the fitted image pose by well under 0.05 mm and 0.05° (the image spans ~0.1 m).
    T_a, T_b = from_images.T_Ptip_I, from_points.T_Ptip_I
    np.testing.assert_allclose(T_a[:3, 3], T_b[:3, 3], atol=5e-5)
    angle = np.degrees(np.arccos(np.clip((np.trace(T_a[:3, :3].T @ T_b[:3, :3]) - 1) / 2, -1, 1)))
    assert angle < 0.05
