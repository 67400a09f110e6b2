"""N-wire segmentation of a TRUS probe on a brachytherapy stepper, and segmentation whatever the poses.

Specifications:
- segmentation reads the image alone: frames without any pose are segmented, their poses
  recorded as missing (not as a segmentation failure), and a calibration does not use them;
- the pose streams are named by the device set (a tracker's ``ProbeToTracker``/``ReferenceToTracker``,
  a stepper's ``ProbeToStepperHome``/``TemplateToStepperHome``) or by options;
- on PLUS's iCal recordings (USTC random stepper motion), brachycal segments ≥ 95 % of the frames
  PLUS segmented, its points within 1 px of PLUS's at the 95th percentile.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import reference

from brachycal.cli.main import main
from brachycal.data.formats.metaimage import read_image_sequence, write_image_sequence
from brachycal.data.formats.plus_files import (
    PoseStreams,
    read_plus_config,
    read_pose_streams,
    read_segmented_frames,
)
from brachycal.data.formats.plus_segmentation import read_segmentation_parameters
from brachycal.imaging import NWireSegmentationParameters, nwire_geometry, segment_frame, segment_sequence
from brachycal.studies.example_files import render_wire_frame as render

STEPPER = "plus_trus_stepper"
ICAL = "PlusDeviceSet_iCal_SonixTouch_BlackTargetGuideStepper_1.1.xml"
STEPPER_POSES = ("ProbeToStepperHomeTransform", "TemplateToStepperHomeTransform")


def _fcal():
    """The fCal 2.0 device set and rendered frames of its phantom (test_nwire_segmentation's)."""
    from test_nwire_segmentation import _write_config, fcal2_points

    return _write_config, fcal2_points


def _rendered(tmp_path, count: int, fields) -> tuple:
    write_config, points = _fcal()
    rng = np.random.default_rng(11)
    truths = [points(offset_u=du) for du in np.linspace(-8.0, 6.0, count)]
    frames = np.stack([render(np.array(list(t.values())), rng) for t in truths])
    write_image_sequence(tmp_path / "seq.mha", frames, frame_fields=fields)
    return read_image_sequence(tmp_path / "seq.mha"), write_config(tmp_path / "config.xml"), truths


def test_frames_without_any_pose_are_segmented(tmp_path):
    sequence, config_path, truths = _rendered(tmp_path, 3, [{} for _ in range(3)])
    config = read_plus_config(config_path)
    params = NWireSegmentationParameters()
    for poses in (PoseStreams(), PoseStreams("ProbeToStepperHome", "TemplateToStepperHome", "stepper"), None):
        result = segment_sequence(sequence, config, params, source="seq.mha", poses=poses)
        assert result.found == 3 and result.skipped == {}
        assert result.without_pose == (0 if poses is None else 3)
        for frame, truth in zip(result.frames, truths, strict=True):
            assert frame.ok and not frame.usable
            assert frame.T_tracker_probe is None and frame.pose_status == ("MISSING", "MISSING")
            for name, uv in truth.items():
                assert np.linalg.norm(frame.points_px[name] - uv) < 0.1  # the rendered frames' goal


def test_stepper_poses_are_copied_by_name(tmp_path):
    """A stepper's streams, named by option: the poses read are the recording's, in metres."""
    probe = "1 0 0 0 0 1 0 0 0 0 1 -51.5 0 0 0 1"
    template = "1 0 0 0 0 1 0 0 0 0 1 2.5 0 0 0 1"
    fields = [
        {"ProbePosition": "-51.5", "ProbeToStepperHomeTransform": probe, "TemplateToStepperHomeTransform": template}
    ] * 2
    _, config_path, _ = _rendered(tmp_path, 2, fields)
    argv = ["nwire", "segment", str(tmp_path / "seq.mha"), "--config", str(config_path), "--quiet"]
    options = ["--probe-transform", "ProbeToStepperHome", "--reference-transform", "TemplateToStepperHomeTransform"]
    assert main([*argv, *options, "--out", str(tmp_path / "f.xml")]) == 0
    calibration, _ = read_segmented_frames(tmp_path / "f.xml", poses=STEPPER_POSES)
    assert [f.usable for f in calibration] == [True, True]
    np.testing.assert_allclose(calibration[0].T_tracker_probe[:3, 3], [0.0, 0.0, -0.0515], atol=1e-12)
    np.testing.assert_allclose(calibration[0].T_tracker_reference[:3, 3], [0.0, 0.0, 0.0025], atol=1e-12)
    # --images-only: the same points, no poses read
    assert main([*argv, "--images-only", "--out", str(tmp_path / "g.xml")]) == 0
    images_only, _ = read_segmented_frames(tmp_path / "g.xml")
    assert [(f.ok, f.usable) for f in images_only] == [(True, False)] * 2
    for a, b in zip(calibration, images_only, strict=True):
        assert a.points_px.keys() == b.points_px.keys()
        for name in a.points_px:
            np.testing.assert_allclose(a.points_px[name], b.points_px[name], atol=1e-9)


def test_a_frame_segmented_without_its_pose_is_read_and_not_used(tmp_path):
    """PLUS's fCal frames, the first OK one's probe pose recorded as INVALID: `brachycal nwire`
    calibrates from the others (one frame fewer), it does not refuse the file."""
    import xml.etree.ElementTree as ET

    from brachycal.calibration.phantom.nwire_file import calibrate_nwire_files

    config = reference("plus_fcal_nwire", "PlusDeviceSet_fCal_Sim_SpatialCalibration_2.0.xml")
    frames = reference("plus_fcal_nwire", "fCal_3NWires_segmented_frames.xml")
    tree = ET.parse(frames)
    first = next(f for f in tree.getroot().iterfind(".//CalibrationData/Frame") if f.get("SegmentationStatus") == "OK")
    status = next(e for e in first.iter("CustomFrameField") if e.get("Name") == "ProbeToTrackerTransformStatus")
    status.set("Value", "INVALID")
    tree.write(tmp_path / "frames.xml")
    whole = calibrate_nwire_files(config, frames)
    edited = calibrate_nwire_files(config, tmp_path / "frames.xml")
    assert edited.frames_used == whole.frames_used - 1
    assert edited.calibration_points == whole.calibration_points - 3  # one middle-wire point per N


def test_the_device_set_names_the_pose_streams():
    assert read_pose_streams(reference(STEPPER, ICAL)) == PoseStreams(
        "ProbeToStepperHome", "TemplateToStepperHome", "stepper"
    )
    fcal = reference("plus_fcal_nwire", "PlusDeviceSet_fCal_Sim_SpatialCalibration_2.0.xml")
    assert read_pose_streams(fcal) == PoseStreams("ProbeToTracker", "ReferenceToTracker", "tracker")


@pytest.mark.parametrize(
    ("sequence", "which", "frames"),
    [
        ("USTC_3NWires_RandomStepperMotionCalibration.igs.mha", 0, (0, 14, 18, 100, 211)),
        ("USTC_3NWires_RandomStepperMotionValidation.igs.mha", 1, (0, 41, 105)),
    ],
)
def test_stepper_frames_give_plus_points(sequence, which, frames):
    """A few frames of each (those PLUS could not segment among them: 14–18, 40–42), quickly."""
    config_path = reference(STEPPER, ICAL)
    plus = read_segmented_frames(reference(STEPPER, "UsTemplateCalibration_3NWires.results.xml"), poses=STEPPER_POSES)[
        which
    ]
    images = read_image_sequence(reference(STEPPER, sequence))
    geometry = nwire_geometry(read_plus_config(config_path, require_registration=False).patterns)
    params = read_segmentation_parameters(config_path)
    for k in frames:
        result = segment_frame(images.pixels[k], geometry, params, orientation="MF")
        assert (result.points_px is not None) == plus[k].ok, f"frame {k}: {result.reason}"
        for name, uv in plus[k].points_px.items() if plus[k].ok else ():
            assert np.linalg.norm(result.points_px[name] - uv) < 0.01, (k, name)  # PLUS's 6 printed digits


@pytest.mark.slow
@pytest.mark.parametrize(
    ("sequence", "which"),
    [
        ("USTC_3NWires_RandomStepperMotionCalibration.igs.mha", 0),
        ("USTC_3NWires_RandomStepperMotionValidation.igs.mha", 1),
    ],
)
def test_stepper_recordings_give_plus_points(sequence, which):
    """The goal against PLUS: ≥ 95 % of the frames PLUS segmented, p95 point distance ≤ 1 px
    (measured: every one of PLUS's frames, p95 0.0006 px: PLUS's points to its printed digits)."""
    config_path = reference(STEPPER, ICAL)
    poses = read_pose_streams(config_path)
    plus = read_segmented_frames(reference(STEPPER, "UsTemplateCalibration_3NWires.results.xml"), poses=poses.fields)
    images = read_image_sequence(reference(STEPPER, sequence))
    result = segment_sequence(
        images,
        read_plus_config(config_path, require_registration=False),
        read_segmentation_parameters(config_path),
        source=sequence,
        poses=poses,
        require_poses=True,
    )
    assert len(plus[which]) == len(images) and result.without_pose == 0
    plus_ok = [k for k, frame in enumerate(plus[which]) if frame.ok]
    both = [k for k in plus_ok if result.frames[k].ok]
    assert len(both) >= 0.95 * len(plus_ok)
    distances = [
        np.linalg.norm(result.frames[k].points_px[name] - uv)
        for k in both
        for name, uv in plus[which][k].points_px.items()
    ]
    assert np.percentile(distances, 95) <= 1.0
    # the poses carried are the stepper's, as PLUS's results file has them for the same frames
    k = both[0]
    np.testing.assert_allclose(result.frames[k].T_tracker_probe, plus[which][k].T_tracker_probe, atol=1e-6)
