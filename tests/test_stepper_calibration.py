"""Stepper calibration of a TRUS probe: pixel spacing and centre of rotation from N-wire frames.

Specifications:
- on exact synthetic frames (PLUS's iCal phantom seen across its wires, the image turned about a
  known centre, known anisotropic spacing) both are returned exactly;
- a gross outlier is rejected (PLUS's 3 SD rule) and the fit stays exact, its residual statistics
  those of the kept equations;
- too few frames, too few Ns, or a recording without rotation are refused as degenerate;
- on PLUS's probe-rotation recording, both match PLUS's regression baseline;
- translation axes: on exact frames of wires tilted against the image normal, the probe's slope is
  (wire direction − probe axis), the template's (template axis − wire direction), and their sum the
  template axis relative to the probe axis, whatever the wires' direction;
- the rotation axis's tilt is recovered from two probe positions, and not given (with the reason)
  from one; the rotation encoder's scale is recovered;
- every stated SD matches the spread of the estimate over fresh noise draws (within a band that a
  SD off by a third would leave);
- a translation shorter than 5 mm, a rotation under 10°, or an axis that does not move is refused.
"""

from __future__ import annotations

import json
import math
import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from conftest import reference

from brachycal.calibration import centre_of_rotation, pixel_spacing
from brachycal.calibration.phantom.stepper import (
    MIN_ROTATION_FRAMES,
    centre_sd,
    jackknife_spacing_sd,
    relative_axis,
    rotation_axis,
    rotation_encoder,
    rotation_equations,
    spacing_equations,
    translation_axis,
)
from brachycal.data.formats.metaimage import read_image_sequence, read_sequence_header
from brachycal.data.formats.plus_files import Wire, read_plus_config, stepper_encoder_values
from brachycal.data.formats.plus_segmentation import read_segmentation_parameters
from brachycal.errors import DegenerateDataError, InputError
from brachycal.imaging import segment_sequence
from brachycal.studies import stepper_twin

STEPPER = "plus_trus_stepper"
ICAL = "PlusDeviceSet_iCal_SonixTouch_BlackTargetGuideStepper_1.1.xml"

#: PLUS's iCal 1.1 phantom (its device set's PhantomDefinition): three Ns of three wires along z.
PATTERNS = [tuple(stepper_twin.wires()[3 * k : 3 * k + 3]) for k in range(3)]
SPACING = np.array([0.147e-3, 0.1424e-3])  # m/px, anisotropic as the SonixTouch's
CENTRE_PX = np.array([414.09, 22.59])


def rotation_frames(angles_deg, along=0.5):
    """Wire points of frames turned about CENTRE_PX: the image plane at fraction ``along`` of the
    wires (the diagonal's dot moves with it), phantom cross-section 60 mm below the centre."""
    frames = []
    for angle in np.radians(angles_deg):
        R = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
        points = {}
        for pattern in PATTERNS:
            for wire in pattern:
                xy = wire.front_m[:2] + along * (wire.back_m[:2] - wire.front_m[:2])
                q = np.array([xy[0] - 0.030, 0.060 - xy[1] + 0.030])  # phantom x → u, y down the image
                points[wire.name] = (CENTRE_PX * SPACING + R @ q) / SPACING
        frames.append(points)
    return frames


def test_exact_frames_give_the_spacing_and_the_centre_exactly():
    frames = rotation_frames(np.linspace(-20.0, 25.0, 40))
    spacing = pixel_spacing(frames, PATTERNS)
    np.testing.assert_allclose(spacing.value, SPACING, rtol=1e-9)
    assert spacing.equations == 40 * 4  # two Ns with a neighbour, two equations each
    # (how many the 3 SD rule keeps of exact equations is a matter of round-off: not asserted)
    centre = centre_of_rotation(frames, PATTERNS, spacing.value)
    np.testing.assert_allclose(centre.value, CENTRE_PX, atol=1e-6)
    assert abs(centre.residual_mean) < 1e-12 and centre.residual_sd < 1e-12  # m²: exact


def test_the_equations_are_plus_s():
    """Spacing: the side wires of each N but the last, and the neighbouring Ns' last wires (40 mm
    and 20 mm on this phantom); centre: frame i with frames i+1, i+3, … (PLUS's pairing), six side
    wires a pair."""
    frames = rotation_frames([0.0, 10.0, 20.0, 30.0])
    _, b = spacing_equations(frames, PATTERNS)
    np.testing.assert_allclose(np.sqrt(b[:4]), [0.040, 0.020, 0.040, 0.020], atol=1e-12)
    _, b = rotation_equations(frames, PATTERNS, SPACING)
    assert len(b) == 6 * (2 + 1 + 1)  # (0,1) (0,3) (1,2) (2,3)


def test_a_gross_outlier_is_rejected():
    frames = rotation_frames(np.linspace(-20.0, 25.0, 40))
    frames[7]["Wire3"] = frames[7]["Wire3"] + np.array([25.0, -18.0])  # one dot 30 px off
    spacing = pixel_spacing(frames, PATTERNS)
    np.testing.assert_allclose(spacing.value, SPACING, rtol=1e-9)
    # Wire3's two equations of frame 7 are ~5e-6 m² off: the kept equations' residuals are round-off
    assert spacing.kept <= spacing.equations - 2 and spacing.residual_sd < 1e-15
    centre = centre_of_rotation(frames, PATTERNS, SPACING)
    np.testing.assert_allclose(centre.value, CENTRE_PX, atol=1e-6)
    assert centre.kept < centre.equations


def test_degenerate_recordings_are_refused():
    with pytest.raises(DegenerateDataError, match=f"at least {MIN_ROTATION_FRAMES}"):
        centre_of_rotation(rotation_frames(np.linspace(0, 20, MIN_ROTATION_FRAMES - 1)), PATTERNS, SPACING)
    with pytest.raises(DegenerateDataError, match="do not determine"):  # no rotation: the dots never move
        centre_of_rotation(rotation_frames([5.0] * 40), PATTERNS, SPACING)
    with pytest.raises(DegenerateDataError, match="two N patterns"):
        pixel_spacing(rotation_frames([0.0, 10.0]), PATTERNS[:1])


@pytest.mark.slow  # segments the 142 frames: ~5 s of CPU
def test_plus_probe_rotation_recording_gives_plus_baseline():
    """PLUS's regression baseline for this recording (its stepper-calibration tests): measured here
    0.147096 × 0.142394 mm/px (1e-7 and 2.5e-7 mm/px from PLUS's) and (414.092, 22.591) px
    (0.002 px from PLUS's): PLUS solves by LSQR iterations, brachycal exactly."""
    config_path = reference(STEPPER, ICAL)
    baseline = ET.parse(reference(STEPPER, "USTC_3NWires_StepperCalibrationResultBaseline.xml")).getroot()
    plus_spacing = np.array(baseline.find("SpacingCalibrationResult").get("Spacing").split(), float) * 1e-3
    plus_centre = np.array(baseline.find("CenterOfRotationCalibrationResult").get("CenterOfRotationPx").split(), float)
    config = read_plus_config(config_path, require_registration=False)
    sequence = read_image_sequence(reference(STEPPER, "USTC_3NWires_ProbeRotation.igs.mha"))
    result = segment_sequence(
        sequence, config, read_segmentation_parameters(config_path), source="rotation", poses=None
    )
    frames = [f.points_px for f in result.frames if f.ok]
    spacing = pixel_spacing(frames, config.patterns)
    # 1e-5 relative: 0.006 px over the 600 px image; PLUS's and our segmentation agree to 1e-3 px
    np.testing.assert_allclose(spacing.value, plus_spacing, rtol=1e-5)
    centre = centre_of_rotation(frames, config.patterns, spacing.value)
    np.testing.assert_allclose(centre.value, plus_centre, atol=0.01)


SIDES = [wire for pattern in PATTERNS for wire in (pattern[0], pattern[2])]
PROBE_AXIS = np.array([0.012, -0.031, 1.0])  # per metre of the encoder
TEMPLATE_AXIS = np.array([-0.004, 0.022, 1.0])
WIRE_DIRECTION = np.array([0.017, 0.045, 1.0])  # the phantom's wires, against the image normal


def _dot(wire: Wire, probe_m: float, template_m: float) -> np.ndarray:
    """Pixel of ``wire``'s dot: the image plane is z = 0 of the probe, moved by ``probe_m`` along the
    probe axis; the phantom (its wires along WIRE_DIRECTION) moved by ``template_m`` along the template
    axis. The intersection is solved in 3D (an oracle the fit does not share)."""
    start = np.array([wire.front_m[0], wire.front_m[1], 0.02]) + template_m * TEMPLATE_AXIS
    origin = probe_m * PROBE_AXIS
    t = (origin[2] - start[2]) / WIRE_DIRECTION[2]  # where the wire crosses the image plane
    xy = (start + t * WIRE_DIRECTION - origin)[:2]
    return (xy + np.array([0.010, 0.005])) / SPACING


def translation_frames(probe_m, template_m, rng=None, noise_px=0.0):
    frames = []
    for p, t in zip(probe_m, template_m, strict=True):
        points = {}
        for wire in SIDES:
            points[wire.name] = _dot(wire, p, t) + (rng.normal(0.0, noise_px, 2) if noise_px else 0.0)
        frames.append(points)
    return frames


def test_exact_translation_frames_give_both_axes_and_their_difference():
    z = np.linspace(-0.060, -0.010, 30)
    still = np.zeros_like(z)
    probe = translation_axis(translation_frames(z, still), z, PATTERNS, SPACING)
    template = translation_axis(translation_frames(still, z), z, PATTERNS, SPACING)
    np.testing.assert_allclose(probe.slope, (WIRE_DIRECTION - PROBE_AXIS)[:2], atol=1e-9)
    np.testing.assert_allclose(template.slope, (TEMPLATE_AXIS - WIRE_DIRECTION)[:2], atol=1e-9)
    relative, _ = relative_axis(probe, template)
    np.testing.assert_allclose(relative, (TEMPLATE_AXIS - PROBE_AXIS)[:2], atol=1e-9)
    # PLUS's orientation form: (−t_x, t_y, 1)
    np.testing.assert_allclose(probe.plus_orientation, [-probe.slope[0], probe.slope[1], 1.0])
    assert probe.range_m == pytest.approx(0.050) and probe.frames == 30


def test_translation_slope_sd_matches_the_spread_over_noise_draws():
    """The stated SD (from the fit's covariance) is the spread of the slope over fresh 0.5 px noise
    draws: within ±15 % (300 draws: the spread's own SD is ~4 %)."""
    rng = np.random.default_rng(7)
    z = np.linspace(-0.030, 0.0, 25)
    fits = [translation_axis(translation_frames(z, 0 * z, rng, 0.5), z, PATTERNS, SPACING) for _ in range(300)]
    spread = np.std([f.slope for f in fits], axis=0, ddof=1)
    stated = np.mean([f.slope_sd for f in fits], axis=0)
    np.testing.assert_array_less(np.abs(stated / spread - 1.0), 0.15)


def test_centre_sd_matches_the_spread_over_noise_draws():
    """The centre's SD (the dots' noise, estimated from the radial residuals, propagated through the
    whole fit) is the spread of the centre over fresh 0.8 px noise draws: within ±30 %."""
    rng = np.random.default_rng(11)
    clean = rotation_frames(np.linspace(-20.0, 25.0, 36))
    centres, stated = [], []
    for _ in range(40):
        frames = [{name: uv + rng.normal(0.0, 0.8, 2) for name, uv in points.items()} for points in clean]
        fit = centre_of_rotation(frames, PATTERNS, SPACING)
        sd, _ = centre_sd(frames, PATTERNS, SPACING, fit.value, draws=20)
        centres.append(fit.value)
        stated.append(sd)
    spread = np.std(centres, axis=0, ddof=1)
    np.testing.assert_array_less(np.abs(np.mean(stated, axis=0) / spread - 1.0), 0.3)


def test_spacing_sd_matches_the_spread_over_noise_draws():
    """The spacing's jackknife SD over frames is the spread of the spacing over fresh 0.8 px draws: ±30 %."""
    rng = np.random.default_rng(5)
    clean = rotation_frames(np.linspace(-20.0, 25.0, 30))
    values, stated = [], []
    for _ in range(60):
        frames = [{name: uv + rng.normal(0.0, 0.8, 2) for name, uv in points.items()} for points in clean]
        values.append(pixel_spacing(frames, PATTERNS).value)
        stated.append(jackknife_spacing_sd(frames, PATTERNS))
    spread = np.std(values, axis=0, ddof=1)
    np.testing.assert_array_less(np.abs(np.mean(stated, axis=0) / spread - 1.0), 0.3)


def test_rotation_tilt_from_two_probe_positions_and_none_from_one():
    angles = np.linspace(-20.0, 25.0, 40)
    tilt = np.array([0.02, -0.01])  # the centre's drift, image metres per metre of probe position
    frames, positions = [], []
    for z in (-0.05, -0.02):
        shift = tilt * z / SPACING  # px
        frames += [{k: uv + shift for k, uv in f.items()} for f in rotation_frames(angles)]
        positions += [z] * len(angles)
    encoder = np.radians(np.concatenate([angles, angles]))
    axis = rotation_axis(frames, encoder, positions, PATTERNS, SPACING, draws=5)
    assert axis.tilt is not None and axis.tilt_note == ""
    np.testing.assert_allclose(axis.tilt, tilt, atol=1e-9)
    one = rotation_axis(frames[:40], encoder[:40], positions[:40], PATTERNS, SPACING, draws=5)
    assert one.tilt is None and "one probe position" in one.tilt_note
    np.testing.assert_allclose(one.centre_px, CENTRE_PX + tilt * -0.05 / SPACING, atol=1e-6)


def test_rotation_encoder_scale_is_recovered():
    """Frames turned by 0.9 × the encoder's angle: PLUS's angle of the side-wire line turns by −0.9×
    (its scale, −k, is 0.9), offset 0 (the lines are level at angle 0)."""
    encoder = np.linspace(-30.0, 30.0, 40)
    fit = rotation_encoder(rotation_frames(0.9 * encoder), np.radians(encoder), PATTERNS, SPACING)
    assert fit.scale == pytest.approx(-0.9, abs=1e-9)
    assert fit.offset_rad == pytest.approx(0.0, abs=1e-9)


def test_short_or_still_axes_are_refused():
    z = np.linspace(0.0, 0.004, 10)  # 4 mm
    with pytest.raises(DegenerateDataError, match="covers only 4 mm"):
        translation_axis(translation_frames(z, 0 * z), z, PATTERNS, SPACING)
    still = np.zeros(10)
    with pytest.raises(DegenerateDataError, match="does not move"):
        translation_axis(translation_frames(still, still), still, PATTERNS, SPACING)
    angles = np.linspace(0.0, 8.0, 40)  # 8°
    with pytest.raises(DegenerateDataError, match="covers only 8"):
        rotation_axis(rotation_frames(angles), np.radians(angles), np.zeros(40), PATTERNS, SPACING)


@pytest.mark.slow  # segments the three recordings (524 frames): ~20 s of CPU
def test_plus_stepper_recordings_give_plus_baseline_and_every_axis(tmp_path, capsys):
    """``brachycal stepper calibrate`` on PLUS's three recordings: spacing and centre as PLUS's baseline
    (with PLUS's residual statistics, mm² in its file), the tilt not given (one probe position), both
    translation axes with SDs, every value finite in the file."""
    from brachycal.cli.main import main

    baseline = ET.parse(reference(STEPPER, "USTC_3NWires_StepperCalibrationResultBaseline.xml")).getroot()
    plus_spacing = baseline.find("SpacingCalibrationResult")
    plus_centre = baseline.find("CenterOfRotationCalibrationResult")
    recordings = [
        reference(STEPPER, f"USTC_3NWires_{name}.igs.mha")
        for name in ("ProbeRotation", "ProbeTranslation", "TemplateTranslation")
    ]
    out = tmp_path / "stepper.json"
    argv = ["stepper", "calibrate", *map(str, recordings), "--config", str(reference(STEPPER, ICAL)), "--out", str(out)]
    assert main([*argv, "--quiet"]) == 0
    assert "centre of rotation" in capsys.readouterr().out
    result = json.loads(out.read_text())
    assert result["format"] == "brachycal-stepper/1"
    spacing, centre = result["pixel_spacing"], result["centre_of_rotation"]
    np.testing.assert_allclose(
        spacing["value_mm_per_px"], np.array(plus_spacing.get("Spacing").split(), float), rtol=1e-5
    )
    np.testing.assert_allclose(
        centre["value_px"], np.array(plus_centre.get("CenterOfRotationPx").split(), float), atol=0.01
    )
    for fit, plus in ((spacing, plus_spacing), (centre, plus_centre)):  # m² vs PLUS's mm²
        assert fit["residual_mean_m2"] * 1e6 == pytest.approx(float(plus.get("ErrorMean")), rel=0.01)
        assert fit["residual_sd_m2"] * 1e6 == pytest.approx(float(plus.get("ErrorStdev")), rel=0.01)
    axis = result["rotation_axis"]
    assert axis["determined"] is False and axis["tilt"] is None and "one probe position" in axis["note"]
    # each SD is positive and far below its value's scale (recordings that determine it)
    assert 0 < min(spacing["sd_m_per_px"]) and max(spacing["sd_m_per_px"]) < 1e-3 * min(spacing["value_m_per_px"])
    assert 0 < min(centre["sd_px"]) and max(centre["sd_px"]) < 2.0
    for name in ("probe_translation_axis", "template_translation_axis"):
        assert 0 < min(result[name]["slope_sd"]) and max(result[name]["slope_sd"]) < 0.005
        assert result[name]["angle_to_wires_deg"] < 5.0  # the wires run along the probe
        assert result[name]["frames"] == result["recordings"][name.removesuffix("_axis")]["segmented"]


def test_angle_and_encoder_sds_match_the_spread_over_noise_draws():
    """The translation axis's angle to the wires (first-order SD from the slopes') and the rotation
    encoder's scale (SD from the fit's covariance) spread over fresh noise draws as stated: ±20 %."""
    rng = np.random.default_rng(3)
    z = np.linspace(-0.030, 0.0, 25)
    fits = [translation_axis(translation_frames(z, 0 * z, rng, 0.5), z, PATTERNS, SPACING) for _ in range(300)]
    spread = np.std([f.angle_deg for f in fits], ddof=1)
    assert abs(np.mean([f.angle_sd_deg for f in fits]) / spread - 1.0) < 0.2
    encoder = np.linspace(-30.0, 30.0, 40)
    clean = rotation_frames(0.9 * encoder)
    scales, stated = [], []
    for _ in range(300):
        frames = [{name: uv + rng.normal(0.0, 0.8, 2) for name, uv in points.items()} for points in clean]
        fit = rotation_encoder(frames, np.radians(encoder), PATTERNS, SPACING)
        scales.append(fit.scale)
        stated.append(fit.scale_sd)
    assert abs(np.mean(stated) / np.std(scales, ddof=1) - 1.0) < 0.2


def test_tilt_sd_matches_the_spread_over_noise_draws():
    """From two probe positions (no residual degree of freedom) the tilt's SD comes from each
    position's centre SD; it matches the tilt's spread over fresh 0.8 px draws: ±35 % (30 draws)."""
    rng = np.random.default_rng(13)
    angles = np.linspace(-20.0, 25.0, 32)
    clean, positions = [], []
    for z in (-0.05, -0.02):
        clean += rotation_frames(angles)
        positions += [z] * len(angles)
    encoder = np.radians(np.concatenate([angles, angles]))
    tilts, stated = [], []
    for _ in range(30):
        frames = [{name: uv + rng.normal(0.0, 0.8, 2) for name, uv in points.items()} for points in clean]
        axis = rotation_axis(frames, encoder, positions, PATTERNS, SPACING, draws=15)
        assert axis.tilt is not None and axis.tilt_sd is not None
        tilts.append(axis.tilt)
        stated.append(axis.tilt_sd)
    spread = np.std(tilts, axis=0, ddof=1)
    np.testing.assert_array_less(np.abs(np.mean(stated, axis=0) / spread - 1.0), 0.35)


@pytest.mark.parametrize(
    ("recording", "field", "size", "unit"),
    [("ProbeTranslation", "ProbePosition", 10.0, "cm"), ("ProbeRotation", "ProbeRotation", 180 / math.pi, "radians")],
)
def test_an_encoder_in_another_unit_than_its_poses_is_refused(tmp_path, recording, field, size, unit):
    """PLUS's own recordings carry each encoder and the pose it drives (mm, degrees): read as they are,
    and refused naming the field and the likely unit when the encoder is rewritten in cm or radians
    (the header only: the frames are never decoded)."""
    source = reference(STEPPER, f"USTC_3NWires_{recording}.igs.mha")
    values = stepper_encoder_values(read_sequence_header(source)[1], source)
    assert np.ptp(values[:, 0 if field == "ProbePosition" else 1]) > 0.01  # it moves (m or rad)
    marker = b"ElementDataFile = LOCAL\n"
    head, _, body = source.read_bytes().partition(marker)
    text = re.sub(
        rf"(Seq_Frame\d+_{field} = )(\S+)", lambda m: f"{m.group(1)}{float(m.group(2)) / size:.6g}", head.decode()
    )
    rewritten = tmp_path / f"{recording}_{unit}.mha"
    rewritten.write_bytes(text.encode() + marker + body)
    with pytest.raises(InputError, match=rf"column '{field}': .*looks like {unit}"):
        stepper_encoder_values(read_sequence_header(rewritten)[1], rewritten)
