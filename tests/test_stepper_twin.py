"""The bundled stepper twin (``examples/stepper``): the stepper commands run on it and recover its truth.

Specifications:
- the twin's files are PLUS's: the device set reads as a stepper's (its axes, template, phantom and
  segmentation settings), every recording carries the stepper's encoder fields and poses;
- its truth is geometry, not a fit: each frame's wire points are the wires' crossings of the image
  plane (a wire point projected back lies on its wire), the centre of rotation is where the probe's
  axis crosses the plane, and the translation axes' image-plane orientations follow from the axes;
- without segmentation noise, ``stepper calibrate`` gives the spacing, the centre of rotation, the
  encoder's scale and both axes up to what rendering and segmentation leave (bounds below,
  :data:`EXACT`); ``stepper image`` gives Image → Probe within 0.1 mm over the image and the
  phantom's registration within 0.05 mm;
- on the bundled twin (0.3 px of noise), every stepper value is within 4 of its stated SDs (plus
  the noise-free bound) of the truth; Image → Probe within 1 mm over the image (measured 0.55 mm
  at its corners), the registration within 0.3 mm;
- ``stepper template`` puts a hole where the truth's chain does (within the Image → Probe bound),
  and ``stepper export`` writes its files.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT

from brachycal.calibration.phantom.stepper_probe import read_stepper_image, stepper_pose
from brachycal.cli.main import main
from brachycal.data.formats.metaimage import read_sequence_header
from brachycal.data.formats.plus_files import read_plus_config, read_pose_streams, stepper_encoder_values
from brachycal.data.formats.plus_stepper import read_stepper_axes, read_template
from brachycal.io import OutputSet
from brachycal.se3 import inverse, transform_points
from brachycal.studies import stepper_twin
from brachycal.studies.stepper_twin import STEPPER_NAMES, write_stepper_files

MM = 1e-3
EXAMPLES = ROOT / "examples"
RECORDINGS = ("rotation", "probe_translation", "template_translation", "calibration", "validation")
#: What rendering and segmentation leave without noise (measured on the noise-free twin: spacing
#: 5e-6 mm/px, centre 0.09 px, axes 4e-5, scale 5e-4, Image -> Probe 0.04 mm, registration 0.025 mm).
EXACT = {"spacing_mm": 2e-5, "centre_px": 0.2, "axis": 1e-4, "scale": 1e-3, "image_mm": 0.1, "registration_mm": 0.05}


def _run(folder: Path, out: Path) -> tuple[dict, dict, Path]:
    """``stepper calibrate`` and ``stepper image`` on the twin in ``folder``: their results."""
    s = {key: str(folder / name) for key, name in STEPPER_NAMES.items()}
    out.mkdir(exist_ok=True)
    calibrate = ["stepper", "calibrate", s["rotation"], s["probe_translation"], s["template_translation"]]
    assert main([*calibrate, "--config", s["config"], "--out", str(out / "stepper.json"), "--quiet"]) == 0
    image = ["stepper", "image", s["rotation"], s["calibration"], s["validation"], "--config", s["config"]]
    assert main([*image, "--out", str(out / "stepper_image.json")]) == 0
    truth = json.loads(Path(s["truth"]).read_text())
    return json.loads((out / "stepper.json").read_text()), truth, out / "stepper_image.json"


@pytest.fixture(scope="module")
def bundled(tmp_path_factory):
    return _run(EXAMPLES, tmp_path_factory.mktemp("bundled"))


@pytest.fixture(scope="module")
def noise_free(tmp_path_factory):
    folder = tmp_path_factory.mktemp("twin0")
    with OutputSet() as outputs:
        staged = {key: outputs.claim(folder / name, make_parents=True) for key, name in STEPPER_NAMES.items()}
        write_stepper_files(staged, noise_px=0.0)
    return _run(folder, folder / "out")


def test_the_twin_s_files_are_a_stepper_s():
    config = EXAMPLES / STEPPER_NAMES["config"]
    assert read_pose_streams(config).source == "stepper"
    axes = read_stepper_axes(config)
    np.testing.assert_array_equal(axes.probe_translation, stepper_twin.AXES.probe_translation)
    np.testing.assert_array_equal(axes.template_translation, stepper_twin.AXES.template_translation)
    assert len(read_plus_config(config, require_registration=False).patterns) == 3
    template = read_template(config)
    assert {"A7", "D4", "D7", "A4"} <= set(template.holes)
    np.testing.assert_allclose(template.holes["D4"], [0.030, 0.030, 0.0])
    for key in RECORDINGS:
        path = EXAMPLES / STEPPER_NAMES[key]
        _, frames = read_sequence_header(path)
        assert len(stepper_encoder_values(frames, path)) == len(frames) >= 10
        assert all(f["ProbeToStepperHomeTransformStatus"] == "OK" for f in frames)
        assert all(f["TemplateToStepperHomeTransformStatus"] == "OK" for f in frames)
    assert sum((EXAMPLES / name).stat().st_size for name in STEPPER_NAMES.values()) < 300_000


def test_the_truth_is_geometry():
    """A wire point projected back lies on its wire; the centre of rotation is on the probe's axis."""
    d, a, t = -0.052, np.radians(2.5), 0.004
    points = stepper_twin.wire_points(d, a, t)
    T_probe_phantom = (
        inverse(stepper_twin.STEPPER_TWIN.probe_pose(d, a))
        @ stepper_twin.STEPPER_TWIN.template_pose(t)
        @ stepper_twin.T_TEMPLATE_PHANTOM
    )
    M = stepper_twin.image_to_probe()
    for wire in stepper_twin.wires():
        p_probe = M @ [*points[wire.name], 0.0, 1.0]
        p = transform_points(inverse(T_probe_phantom), p_probe[:3][None])[0]
        direction = (wire.back_m - wire.front_m) / np.linalg.norm(wire.back_m - wire.front_m)
        assert np.linalg.norm(np.cross(p - wire.front_m, direction)) < 1e-12  # metres off the wire's line
    centre = M @ [*stepper_twin.centre_of_rotation_px(), 0.0, 1.0]
    np.testing.assert_allclose(centre[:2], 0.0, atol=1e-15)
    # Image axes aligned with the probe's x and -y, and wires along z: PLUS's form is the axis itself.
    np.testing.assert_allclose(stepper_twin.expected_axis_orientation("probe"), [0.004635, -0.05344, 1], atol=1e-3)


def _assert_calibration(result: dict, truth: dict, sds: float) -> None:
    """Every stepper value within ``sds`` of its stated SDs plus the noise-free bound of the truth."""
    spacing = result["pixel_spacing"]
    err = np.abs(np.subtract(spacing["value_mm_per_px"], truth["spacing_mm"]))
    assert np.all(err <= sds * np.array(spacing["sd_mm_per_px"]) + EXACT["spacing_mm"]), err
    centre = result["centre_of_rotation"]
    err = np.abs(np.subtract(centre["value_px"], truth["centre_of_rotation_px"]))
    assert np.all(err <= sds * np.array(centre["sd_px"]) + EXACT["centre_px"]), err
    encoder = result["rotation_encoder"]
    assert abs(encoder["plus_scale"] - truth["rotation_encoder_scale"]) <= sds * encoder["scale_sd"] + EXACT["scale"]
    for key, want in (
        ("probe_translation_axis", "probe_axis_plus_orientation_in_image"),
        ("template_translation_axis", "template_axis_plus_orientation_in_image"),
    ):
        axis = result[key]
        err = np.abs(np.subtract(axis["plus_orientation"], truth[want]))[:2]
        assert np.all(err <= sds * np.array(axis["slope_sd"]) + EXACT["axis"]), (key, err)


def _image_error_mm(path: Path, truth: dict) -> tuple[float, float]:
    """Largest distance (mm) between the estimated and the true Image -> Probe over the image's corners
    and centre; the registration's translation error (mm)."""
    result = read_stepper_image(path)
    width, height = truth["size_px"]
    pixels = np.array([[u, v, 0.0, 1.0] for u in (0, width) for v in (0, height)] + [[width / 2, height / 2, 0, 1]]).T
    diff = (result.image_to_probe - np.array(truth["image_to_probe"])) @ pixels
    registration = result.T_template_phantom[:3, 3] - np.array(truth["T_template_phantom"])[:3, 3]
    return float(np.linalg.norm(diff[:3], axis=0).max() / MM), float(np.linalg.norm(registration) / MM)


def test_without_noise_the_commands_give_the_truth(noise_free):
    result, truth, image = noise_free
    assert truth["noise_px"] == 0.0
    _assert_calibration(result, truth, sds=0.0)
    image_mm, registration_mm = _image_error_mm(image, truth)
    assert image_mm < EXACT["image_mm"] and registration_mm < EXACT["registration_mm"]


def test_the_bundled_twin_gives_its_truth_within_its_stated_sds(bundled):
    result, truth, image = bundled
    assert truth["noise_px"] == stepper_twin.NOISE_PX
    assert result["recordings"]["rotation"]["segmented"] == 36
    _assert_calibration(result, truth, sds=4.0)
    image_mm, registration_mm = _image_error_mm(image, truth)
    assert image_mm < 1.0 and registration_mm < 0.3


def test_template_puts_a_hole_where_the_truth_does(bundled, capsys):
    _, truth, image = bundled
    config = EXAMPLES / STEPPER_NAMES["config"]
    capsys.readouterr()
    argv = ["stepper", "template", str(image), "--config", str(config), "--hole", "D4", "--depth", "100"]
    assert main([*argv, "--probe-position", "-50", "--probe-rotation", "1.5"]) == 0
    row = capsys.readouterr().out.strip().splitlines()[-1].split(",")
    assert row[:2] == ["D4", "100.000"]
    u, v, distance_mm = (float(x) for x in row[2:])
    # The truth's chain, written out: the hole on the template (TemplateHome is the phantom's frame),
    # 100 mm along its z, into the probe at its true pose, into the image.
    p_phantom = np.array(truth["template_holes_mm"]["D4"]) * MM + [0.0, 0.0, 0.100]
    p_stepper = transform_points(np.array(truth["T_template_phantom"]), p_phantom[None])[0]
    T_SH_probe = stepper_pose(-0.050, np.radians(1.5), truth["probe_translation_axis"])
    p_image = transform_points(
        inverse(np.array(truth["T_probe_image"])), transform_points(inverse(T_SH_probe), p_stepper[None])
    )[0]
    spacing = np.array(truth["spacing_mm"]) * MM
    got = np.array([u * spacing[0], v * spacing[1], distance_mm * MM])
    assert np.linalg.norm(got - p_image) < 1.0 * MM  # the bundled twin's Image -> Probe bound


def test_export_writes_plus_and_slicer_files(bundled, tmp_path):
    _, _, image = bundled
    assert main(["stepper", "export", str(image), "--out", str(tmp_path / "ex")]) == 0
    assert {p.name for p in (tmp_path / "ex").iterdir()} >= {"ImageToProbe.tfm", "PlusCoordinateDefinitions.xml"}


def test_poses_as_recorded_are_asked_for_and_said(tmp_path, capsys):
    """Without the device set's StepperCalibration, `stepper image` takes the poses as recorded only
    when asked (--recorded-poses), and says that the axes are then not corrected."""
    s = {key: str(EXAMPLES / name) for key, name in STEPPER_NAMES.items()}
    config = tmp_path / "no_axes.xml"
    lines = Path(s["config"]).read_text().splitlines()
    config.write_text("\n".join(line for line in lines if "<StepperCalibration" not in line))
    assert read_stepper_axes(config) is None
    image = ["stepper", "image", s["rotation"], s["calibration"], s["validation"], "--config", str(config)]
    assert main([*image, "--out", str(tmp_path / "out.json")]) == 2
    assert "--recorded-poses" in capsys.readouterr().err and not (tmp_path / "out.json").exists()
    assert main([*image, "--out", str(tmp_path / "out.json"), "--recorded-poses"]) == 0
    poses = [line for line in capsys.readouterr().out.splitlines() if line.startswith("poses:")]
    assert poses == [
        "poses: as recorded (--recorded-poses): the probe and the template taken to move along the stepper's z "
        "exactly; a stepper axis off z is not corrected and its error goes into Image -> Probe"
    ]
    assert read_stepper_image(tmp_path / "out.json").axes.straight
