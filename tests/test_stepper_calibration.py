"""Stepper calibration of a TRUS probe: pixel spacing and centre of rotation from N-wire frames.

Specifications:
- on exact synthetic frames (PLUS's iCal phantom seen across its wires, the image turned about a
  known centre, known anisotropic spacing) both are returned exactly;
- a gross outlier is rejected (PLUS's 3 SD rule) and the fit stays exact, its residual statistics
  those of the kept equations;
- too few frames, too few Ns, or a recording without rotation are refused as degenerate;
- on PLUS's probe-rotation recording, both match PLUS's regression baseline.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from conftest import reference

from brachycal.calibration import centre_of_rotation, pixel_spacing
from brachycal.calibration.phantom.stepper import MIN_ROTATION_FRAMES, rotation_equations, spacing_equations
from brachycal.data.formats.metaimage import read_image_sequence
from brachycal.data.formats.plus_files import Wire, read_plus_config
from brachycal.data.formats.plus_segmentation import read_segmentation_parameters
from brachycal.errors import DegenerateDataError
from brachycal.imaging import segment_sequence

STEPPER = "plus_trus_stepper"
ICAL = "PlusDeviceSet_iCal_SonixTouch_BlackTargetGuideStepper_1.1.xml"

#: PLUS's iCal 1.1 phantom (its device set's PhantomDefinition), millimetres: wires along z.
ICAL_WIRES = (
    (("Wire1", (49.86, 54.385)), ("Wire2", (39.86, 54.385), (19.86, 54.385)), ("Wire3", (9.86, 54.385))),
    (("Wire4", (49.86, 34.385)), ("Wire5", (19.86, 34.385), (39.86, 34.385)), ("Wire6", (9.86, 34.385))),
    (("Wire7", (39.86, 14.385)), ("Wire8", (29.86, 14.385), (19.86, 14.385)), ("Wire9", (9.86, 14.385))),
)


def _wire(name: str, front_xy, back_xy=None) -> Wire:
    back_xy = front_xy if back_xy is None else back_xy
    return Wire(name, np.array([*front_xy, 62.05]) * 1e-3, np.array([*back_xy, 142.05]) * 1e-3)


PATTERNS = [tuple(_wire(*wire) for wire in pattern) for pattern in ICAL_WIRES]
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
