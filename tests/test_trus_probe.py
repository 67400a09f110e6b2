"""Image → Probe of a TRUS probe on a brachytherapy stepper, and the needle template in the image.

Specifications:
- exact data (a known Image → Probe, phantom registration and stepper axes; wire points generated
  by intersecting the wires with the image plane) give them back to ~1e-9: the registration from
  a rotation recording as PLUS computes it, Image → Probe from random stepper motion with the poses
  rebuilt along the calibrated axes (the poses as recorded, along z only, do not);
- a needle through a template hole lands in the image where the chain says: a point put on the
  image plane comes back at its pixel with distance 0, and the distance grows with the depth;
- on PLUS's iCal recordings, with PLUS's poses brachycal reproduces PLUS's calibration (its
  matrix, 2.153 mm validation and 2.245 mm calibration) and with the poses along the device set's
  calibrated axis validates at or below PLUS's 2.153 mm.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from conftest import reference

from brachycal.calibration.phantom.nwire_file import calibrate_nwire_frames
from brachycal.calibration.phantom.stepper_probe import (
    calibrate_stepper_image_files,
    corrected_frames,
    hole_in_image,
    read_stepper_image,
    register_phantom,
    stepper_pose,
    write_stepper_image,
)
from brachycal.data.formats.plus_files import PlusConfig, SegmentedFrame, Wire
from brachycal.data.formats.plus_stepper import StepperAxes, TemplateGrid, read_stepper_axes, read_template
from brachycal.se3 import from_xyz_rpy, inverse
from brachycal.studies.stepper_twin import ICAL_WIRES_MM  # PLUS's iCal 1.1 phantom (its PhantomDefinition)

MM = 1e-3
STEPPER = "plus_trus_stepper"
ICAL = "PlusDeviceSet_iCal_SonixTouch_BlackTargetGuideStepper_1.1.xml"
#: The truth of the exact data: the rotation axis in the phantom (z = 0), mm; pixel spacing, mm/px.
AXIS_IN_PHANTOM_MM = (29.7, 79.1)
SPACING_MM = (0.147, 0.142)
TILTED_AXES = StepperAxes(np.array([0.004, -0.05, 1.0]), np.array([0.0, 0.0, 1.0]))


def ical_config() -> PlusConfig:
    wires = [Wire(name, np.array(f) * MM, np.array(b) * MM) for name, (f, b) in ICAL_WIRES_MM.items()]
    patterns = [(wires[k], wires[k + 1], wires[k + 2]) for k in (0, 3, 6)]
    return PlusConfig(patterns, {}, 0.145 * MM)


def true_registration() -> np.ndarray:
    T = np.eye(4)
    T[:2, 3] = -np.array(AXIS_IN_PHANTOM_MM) * MM
    return T


def image_to_probe(tilt: bool) -> np.ndarray:
    """PLUS's form (pixels → metres): u along the probe's x, v along −y, the image at the probe's
    rotation axis crossing pixel (414, 22.6) (tilted a little off the cross-section unless not ``tilt``)."""
    rpy = (np.pi + (0.01 if tilt else 0.0), 0.02 if tilt else 0.0, 0.005 if tilt else 0.0)
    T = from_xyz_rpy((0.0, 0.0, 0.16), rpy)
    s = np.array(SPACING_MM) * MM
    T[:3, 3] = T[:3, 3] - T[:3, :2] @ (np.array([414.0, 22.6]) * s)
    M = T.copy()
    M[:3, :3] = T[:3, :3] * np.array([s[0], s[1], s.mean()])
    return M


def project(M: np.ndarray, T_probe_phantom: np.ndarray, config: PlusConfig) -> dict[str, np.ndarray]:
    """Each wire's crossing of the image plane, pixels: the exact segmented points."""
    T_image_phantom = np.linalg.inv(M) @ T_probe_phantom
    out = {}
    for pattern in config.patterns:
        for wire in pattern:
            a = T_image_phantom[:3, :3] @ wire.front_m + T_image_phantom[:3, 3]
            b = T_image_phantom[:3, :3] @ wire.back_m + T_image_phantom[:3, 3]
            hit = a + (-a[2] / (b[2] - a[2])) * (b - a)
            out[wire.name] = hit[:2]
    return out


def frames(M, config, readings, axes: StepperAxes, label: str) -> list[SegmentedFrame]:
    """Exact frames at encoder ``readings`` ``[(d_m, θ_rad)]``: the probe truly moves along ``axes``,
    the recorded poses (as PLUS records them) along z."""
    out = []
    for k, (d, theta) in enumerate(readings):
        T_SH_probe = stepper_pose(d, theta, axes.probe_translation)
        points = project(M, inverse(T_SH_probe) @ true_registration(), config)
        recorded = stepper_pose(d, theta)
        out.append(
            SegmentedFrame(
                k,
                True,
                points,
                recorded,
                np.eye(4),
                source="synthetic",
                label=f"{label} Frame",
                pose_names=("ProbeToStepperHomeTransform", "TemplateToStepperHomeTransform"),
            )
        )
    return out


def random_motion(seed: int, count: int) -> list[tuple[float, float]]:
    rng = np.random.default_rng(seed)
    travel, turn = rng.uniform(-0.095, -0.013, count), np.radians(rng.uniform(-3, 3, count))
    return list(zip(travel.tolist(), turn.tolist(), strict=True))


def test_phantom_registration_is_plus_s_and_exact_on_exact_rotation_frames():
    config = ical_config()
    M = image_to_probe(tilt=False)  # the image across the probe's axis: PLUS's spacing and centre are exact
    rotation = frames(M, config, [(-0.045, np.radians(a)) for a in np.linspace(-32, 35, 40)], TILTED_AXES, "R")
    # the probe at -45 mm along the tilted axis: its rotation axis crosses z = 0 off the stepper's z
    axis_at = TILTED_AXES.probe_translation[:2] * -0.045
    registration = register_phantom([f.points_px for f in rotation], config.patterns, axis_at)
    np.testing.assert_allclose(registration.spacing.value, np.array(SPACING_MM) * MM, rtol=1e-9)
    np.testing.assert_allclose(registration.centre.value, [414.0, 22.6], atol=1e-6)
    np.testing.assert_allclose(registration.T_template_phantom, true_registration(), atol=1e-9)
    # the distances PLUS averages: axis to the middle row of wires, axis to the x = 9.86 mm column
    assert registration.vertical_m == pytest.approx((79.1 - 34.385) * MM + axis_at[1], abs=1e-9)
    assert registration.horizontal_m == pytest.approx((29.7 - 9.86) * MM + axis_at[0], abs=1e-9)


def test_image_to_probe_is_exact_with_poses_along_the_calibrated_axis():
    config = replace(ical_config(), transforms={("Phantom", "Reference"): true_registration()})
    M = image_to_probe(tilt=True)
    calibration = frames(M, config, random_motion(1, 40), TILTED_AXES, "CalibrationData")
    validation = frames(M, config, random_motion(2, 20), TILTED_AXES, "ValidationData")
    fixed = calibrate_nwire_frames(
        config, corrected_frames(calibration, TILTED_AXES), corrected_frames(validation, TILTED_AXES)
    )
    for model in ("affine", "rigid", "3d-aniso", "2d-aniso"):
        np.testing.assert_allclose(fixed.matrix(model), M, atol=1e-9)
        assert fixed.models[model].validation_3d.max_mm < 1e-6
    as_recorded = calibrate_nwire_frames(config, calibration, validation)
    # the recorded poses move the probe along z: 0.05 per mm of travel unaccounted for
    assert as_recorded.models["rigid"].validation_3d.mae_mm > 0.1


def test_a_needle_lands_where_the_chain_says():
    M = image_to_probe(tilt=True)
    T_phantom_template = np.eye(4)
    T_phantom_template[:3, 3] = [0.001, -0.002, 0.0]
    pose = {"probe_translation_m": -0.05, "probe_rotation_rad": np.radians(4.0), "template_translation_m": 0.003}
    # the point on the image plane at pixel (300, 250), carried back to the template frame
    p_probe = M[:3, :2] @ [300.0, 250.0] + M[:3, 3]
    T_SH_probe = stepper_pose(-0.05, np.radians(4.0), TILTED_AXES.probe_translation)
    T_SH_template = stepper_pose(0.003, 0.0, TILTED_AXES.template_translation)
    T_template_grid = inverse(T_SH_template @ true_registration() @ T_phantom_template)
    p_grid = T_template_grid[:3, :3] @ (T_SH_probe[:3, :3] @ p_probe + T_SH_probe[:3, 3]) + T_template_grid[:3, 3]
    grid = TemplateGrid({"D4": np.array([p_grid[0], p_grid[1], 0.0])}, T_phantom_template)
    at = hole_in_image(M, true_registration(), grid, "D4", p_grid[2], axes=TILTED_AXES, **pose)
    assert (at.u_px, at.v_px, at.distance_m) == pytest.approx((300.0, 250.0, 0.0), abs=1e-7)
    deeper = hole_in_image(M, true_registration(), grid, "D4", p_grid[2] + 0.01, axes=TILTED_AXES, **pose)
    # the image is ~1° off the cross-section: 10 mm deeper is ~10 mm off the plane, a few pixels over
    assert abs(deeper.distance_m) == pytest.approx(0.01, rel=1e-3)
    assert np.hypot(deeper.u_px - 300.0, deeper.v_px - 250.0) < 3.0


def test_the_template_is_read_with_its_place_on_the_phantom():
    grid = read_template(reference(STEPPER, ICAL))
    assert len(grid.holes) == 13 * 13
    np.testing.assert_allclose(grid.hole("D4"), [0.030, 0.030, 0.0])
    np.testing.assert_allclose(grid.T_phantom_template, np.eye(4), atol=1e-12)  # both offsets are (5, 63.5) mm
    # the phantom's wires run through the template's grid (within 0.7 mm of a hole)
    for front, _ in ICAL_WIRES_MM.values():
        nearest = min(np.linalg.norm(np.array(front[:2]) * MM - h[:2]) for h in grid.holes.values())
        assert nearest < 0.7 * MM
    axes = read_stepper_axes(reference(STEPPER, ICAL))
    np.testing.assert_allclose(axes.probe_translation, [0.004635, -0.053440, 1.0])


@pytest.fixture(scope="module")
def ical_result(tmp_path_factory):
    """brachycal's stepper calibration on PLUS's segmented frames and its rotation recording."""
    result = calibrate_stepper_image_files(
        reference(STEPPER, ICAL),
        reference(STEPPER, "USTC_3NWires_ProbeRotation.igs.mha"),
        reference(STEPPER, "UsTemplateCalibration_3NWires.results.xml"),
    )
    path = tmp_path_factory.mktemp("ical") / "stepper_image.json"
    write_stepper_image(result, path)
    return result, path


def plus_result() -> tuple[dict[str, float], np.ndarray]:
    """PLUS's 3D statistics (mm) and its Image → Probe (mm) from its results file."""
    from brachycal.data.formats.plus_files import parse_xml, read_coordinate_definitions

    path = reference(STEPPER, "UsTemplateCalibration_3NWires.results.xml")
    stats = next(parse_xml(path).iter("ReprojectionError3DStatistics")).attrib
    return {k: float(v) for k, v in stats.items()}, read_coordinate_definitions(path)["Image", "Probe"]


def test_plus_s_poses_reproduce_plus_s_calibration(ical_result):
    from brachycal.calibration.phantom.nwire import best_fraction

    result, _ = ical_result
    stats, plus_matrix = plus_result()
    plus = result.recorded.models["affine"]
    assert plus.validation_best95.mae_mm == pytest.approx(stats["ValidationMeanMm"], abs=0.005)
    assert plus.validation_best95.sd_mm == pytest.approx(stats["ValidationStdDevMm"], abs=0.005)
    assert best_fraction(plus.calibration_3d).mae_mm == pytest.approx(stats["CalibrationMeanMm"], abs=0.005)
    ours = result.recorded.matrix("affine") * np.array([[1e3], [1e3], [1e3], [1.0]])
    np.testing.assert_allclose(ours[:3, :2], plus_matrix[:3, :2], atol=2e-5)  # mm per pixel
    np.testing.assert_allclose(ours[:3, 3], plus_matrix[:3, 3], atol=0.01)  # mm
    # PLUS's stepper baseline: the centre of rotation the registration used
    np.testing.assert_allclose(result.registration.centre.value, [414.094, 22.592], atol=0.01)


def test_poses_along_the_calibrated_axis_validate_at_or_below_plus(ical_result):
    result, path = ical_result
    chosen = result.nwire.models[result.nwire.model]
    assert chosen.validation_best95.mae_mm <= plus_result()[0]["ValidationMeanMm"]
    # every 3D model improves on its own fit with the poses as recorded
    for model in ("affine", "rigid", "3d-aniso", "3d-iso"):
        assert (
            result.nwire.models[model].validation_best95.mae_mm
            < result.recorded.models[model].validation_best95.mae_mm - 0.2
        )
    stored = read_stepper_image(path)
    np.testing.assert_allclose(stored.image_to_probe, result.nwire.matrix(), atol=1e-12)
    np.testing.assert_allclose(stored.T_template_phantom, result.registration.T_template_phantom, atol=1e-12)


def test_the_hand_off_reads_back_in_millimetres(tmp_path):
    """ImageToProbe.tfm and the PLUS CoordinateDefinitions hold Image → Probe (pixels → mm) and
    Phantom → StepperHome as the result has them; `stepper template` prints a row per hole and depth."""
    from test_hostile_trus_probe import stepper_result

    from brachycal.cli.main import main
    from brachycal.data.formats.plus_files import read_coordinate_definitions
    from brachycal.export import read_itk_transform

    stepper_result(tmp_path / "result.json")
    stored = read_stepper_image(tmp_path / "result.json")
    assert main(["stepper", "export", str(tmp_path / "result.json"), "--out", str(tmp_path / "out")]) == 0
    image_mm = stored.image_to_probe.copy()
    image_mm[:3, :] *= 1e3
    phantom_mm = stored.T_template_phantom.copy()
    phantom_mm[:3, 3] *= 1e3
    np.testing.assert_allclose(read_itk_transform(tmp_path / "out" / "ImageToProbe.tfm"), image_mm, atol=1e-9)
    np.testing.assert_allclose(read_itk_transform(tmp_path / "out" / "PhantomToStepperHome.tfm"), phantom_mm, atol=1e-9)
    definitions = read_coordinate_definitions(tmp_path / "out" / "PlusCoordinateDefinitions.xml")
    np.testing.assert_allclose(definitions["Image", "Probe"], image_mm, rtol=1e-8, atol=1e-8)
    np.testing.assert_allclose(definitions["Phantom", "StepperHome"], phantom_mm, rtol=1e-8, atol=1e-8)


def test_template_prints_one_row_per_hole_and_depth(tmp_path, capsys):
    from test_hostile_trus_probe import device_set, stepper_result

    from brachycal.cli.main import main

    stepper_result(tmp_path / "result.json")
    (tmp_path / "config.xml").write_text(device_set())
    argv = ["stepper", "template", str(tmp_path / "result.json"), "--config", str(tmp_path / "config.xml")]
    assert (
        main([*argv, "--hole", "B2", "--hole", "A3", "--depth", "80", "--depth", "90", "--probe-position", "-40"]) == 0
    )
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("# image frame (pixels)")
    assert lines[1] == "hole,depth_mm,u_px,v_px,distance_from_image_plane_mm"
    rows = [line.split(",") for line in lines[2:]]
    assert [(r[0], r[1]) for r in rows] == [("B2", "80.000"), ("B2", "90.000"), ("A3", "80.000"), ("A3", "90.000")]
    # the image is across the probe's axis: 10 mm deeper is 10 mm further along the image's z
    assert abs(float(rows[1][4]) - float(rows[0][4])) == pytest.approx(10.0, abs=1e-3)


def test_the_axes_of_a_stepper_calibration_are_plus_s(tmp_path):
    """`stepper image --stepper` takes PLUS's form of `stepper calibrate`'s axes and encoder scale."""
    import json

    from brachycal.calibration.phantom.stepper_probe import read_calibrated_axes

    payload = {
        "format": "brachycal-stepper/1",
        "probe_translation_axis": {"slope": [0.026, -0.043], "plus_orientation": [-0.026, -0.043, 1.0]},
        "template_translation_axis": {"slope": [0.0036, 0.0017], "plus_orientation": [-0.0036, 0.0017, 1.0]},
        "rotation_encoder": {"scale": -0.96, "plus_scale": 0.96},
    }
    (tmp_path / "stepper.json").write_text(json.dumps(payload))
    axes = read_calibrated_axes(tmp_path / "stepper.json")
    np.testing.assert_allclose(axes.probe_translation, [-0.026, -0.043, 1.0])
    np.testing.assert_allclose(axes.template_translation, [-0.0036, 0.0017, 1.0])
    assert axes.rotation_encoder_scale == 0.96
    assert not axes.straight


def test_a_pose_that_is_not_a_stepper_s_names_recorded_poses():
    """A recorded pose that moves across z is not an encoder pose: the refusal names the option that
    takes the poses as recorded."""
    from brachycal.calibration.phantom.stepper_probe import encoder_readings, stepper_pose
    from brachycal.errors import InputError

    T = stepper_pose(-0.04, 0.1)
    assert encoder_readings(T) == pytest.approx((-0.04, 0.1))
    T[0, 3] = 1e-3
    with pytest.raises(InputError, match=r"not a stepper encoder pose.*--recorded-poses"):
        encoder_readings(T, what="ProbeToStepperHome")
