"""Wedge lines from rendered B-mode frames: found where the faces truly cross the image, assigned to
their faces, none where there is no wedge; the multi-wedge calibration from them recovers an exact
twin's truth within what their segmentation error predicts."""

from __future__ import annotations

import numpy as np
import pytest

from brachycal.calibration.phantom.features import SEGMENTATION_SD_PX
from brachycal.calibration.phantom.wedge import calibrate_wedge
from brachycal.errors import InputError
from brachycal.imaging import find_lines, find_wedge_lines
from brachycal.se3 import inverse
from brachycal.simulation.bmode import BModeSettings
from brachycal.studies.example_files import NWIRE_SIZE_PX, NWIRE_SPACING_M, NWIRE_T_PROBE_IMAGE
from brachycal.studies.nwire_twin import NWireSimConfig
from brachycal.studies.phantom_images import (
    face_lines_px,
    nominal_face_order,
    render_wedge_frame,
    rendered_wedge_observations,
)
from brachycal.studies.phantom_twin import simulate_phantom

#: The exact twin: every error source of the tracked session off (the images keep speckle, PSF, beam).
EXACT = NWireSimConfig(
    seed=2,
    tracker_noise=False,
    segmentation_noise=False,
    wire_beam_thickness=False,
    phantom_tolerance=False,
    landmark_noise=False,
)


@pytest.fixture(scope="module")
def session():
    return simulate_phantom("wedge", NWIRE_T_PROBE_IMAGE, NWIRE_SPACING_M, NWIRE_SIZE_PX, EXACT, frames=12)


def test_a_rendered_frames_lines_are_found_on_the_true_lines(session):
    phantom = session.phantom
    T_image_phantom = inverse(session.T_phantom_image[0])
    order, slopes = nominal_face_order(phantom, T_image_phantom)
    assert order == ["A1", "A2", "B1", "B2", "C1", "C2"] and slopes == [-1, 1, -1, 1, -1, 1]
    frame = render_wedge_frame(phantom.faces, T_image_phantom, NWIRE_SPACING_M, size_px=NWIRE_SIZE_PX)
    found = find_wedge_lines(frame, order, slopes)
    assert found is not None and list(found) == order
    for name, ends in found.items():
        truth = face_lines_px(phantom.faces, T_image_phantom, NWIRE_SPACING_M, ends[:, 0])[name]
        # Each end within 1 px of the true line in depth: the ends' scatter over the twin's frames is
        # 0.16 px RMS (speckle under a 0.35 mm axial PSF), so 1 px is ~6 SD — and a line put on the
        # beam-smeared leading edge instead of the peak is off by more (the smear of a face tilted
        # ~6° in elevation over the 1.5 mm beam: ±0.2 mm, ~1 px).
        assert np.abs(ends[:, 1] - truth).max() < 1.0, (name, ends[:, 1] - truth)
        # The line spans most of what the face shows (12 mm wide: 40+ columns at 0.19 mm/px).
        assert ends[1, 0] - ends[0, 0] > 40


def test_a_frame_without_wedges_has_no_lines(session):
    phantom = session.phantom
    T_image_phantom = inverse(session.T_phantom_image[0])
    order, slopes = nominal_face_order(phantom, T_image_phantom)
    empty = render_wedge_frame([], T_image_phantom, NWIRE_SPACING_M, size_px=NWIRE_SIZE_PX)
    assert find_lines(empty).shape == (0, 2, 2)
    assert find_wedge_lines(empty, order, slopes) is None
    assert find_lines(np.zeros((720, 1080), dtype=np.uint8)).shape == (0, 2, 2)  # all black: nothing


def test_a_frame_missing_a_face_is_skipped(session):
    phantom = session.phantom
    T_image_phantom = inverse(session.T_phantom_image[0])
    order, slopes = nominal_face_order(phantom, T_image_phantom)
    five = [name for name in order if name != "B2"]
    frame = render_wedge_frame(phantom.faces, T_image_phantom, NWIRE_SPACING_M, size_px=NWIRE_SIZE_PX, shown=five)
    assert len(find_lines(frame)) == 5
    assert find_wedge_lines(frame, order, slopes) is None  # five lines for six faces: not guessed


def test_bad_arguments_are_refused():
    with pytest.raises(InputError, match="2D"):
        find_lines(np.zeros((2, 3, 4), dtype=np.uint8))
    with pytest.raises(InputError, match="slope"):
        find_wedge_lines(np.zeros((4, 4), dtype=np.uint8), ["A1", "A2"], [1])


def test_calibration_from_rendered_frames_of_an_exact_twin_recovers_truth(session):
    segmented = rendered_wedge_observations(session, NWIRE_SPACING_M, NWIRE_SIZE_PX, BModeSettings(seed=5))
    assert segmented.skipped == 0 and len(segmented.observations.frames) == 12
    line_sd_px = float(np.sqrt(np.mean(segmented.line_error_px**2)))
    assert line_sd_px < 0.3  # measured 0.16 px RMS (see above); the bias is ~0.005 px
    fit = calibrate_wedge(session.phantom, segmented.observations)
    # The only error left is the lines' segmentation; the fit's predicted SD 50 mm from the image
    # centre (reach_sd_m) is for SEGMENTATION_SD_PX per line end, and scales with the error: with the
    # measured line error it predicts ~0.1 mm. Points across the image (up to ~40 mm from the lines'
    # centre) must lie within 3 such SDs of the truth (measured: 0.06-0.09 mm RMS over seeds 0-2).
    bound_m = 3.0 * fit.reach_sd_m * line_sd_px / SEGMENTATION_SD_PX
    uv = np.array([[u, v] for u in (340.0, 540.0, 740.0) for v in (100.0, 200.0, 300.0)])
    got = (fit.T_marker_image @ np.c_[uv * fit.spacing_m, np.zeros(9), np.ones(9)].T).T[:, :3]
    want = (NWIRE_T_PROBE_IMAGE @ np.c_[uv * NWIRE_SPACING_M, np.zeros(9), np.ones(9)].T).T[:, :3]
    error_m = np.linalg.norm(got - want, axis=1)
    assert error_m.max() < bound_m, f"{error_m.max() * 1e3:.3f} mm, bound {bound_m * 1e3:.3f} mm"
