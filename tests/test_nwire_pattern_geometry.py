"""A segmented N pattern must fit the phantom's wire layout, or the frame is not segmented.

Specifications:
- the dots of a plane through fCal 2.0's phantom (exact intersections of its wires, any position
  along the wires, the plane tilted, the approximate spacing 8 % off) fit: their misfit stays far
  below the tolerance;
- a bright dot on an N's line between its side dots, where the diagonal is not, passes PLUS's
  checks (line, middle between the sides, lines parallel at the N planes' distances) and is taken
  by them as the diagonal's dot; it puts the diagonal's cut where no one plane cuts the phantom,
  so the pattern is refused and the true, dimmer one taken;
- with no true pattern among the dots, the frame has no pattern: the reason says that no set of
  lines fits the phantom's wire layout, and a sequence counts the frame as not segmented.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from brachycal.data.formats.metaimage import ImageSequence
from brachycal.data.formats.plus_files import PlusConfig, Wire
from brachycal.data.formats.plus_segmentation import NWireSegmentationParameters
from brachycal.imaging.nwire_dots import Dots
from brachycal.imaging.nwire_patterns import NO_FIT, find_pattern, nwire_geometry, phantom_misfit
from brachycal.imaging.nwire_segmentation import segment_sequence
from brachycal.studies.nwire_twin import FCAL2_WIRES_MM

#: fCal 2.0's three Ns (PLUS's phantom definition), millimetres in the phantom frame: the wires run
#: along y, the Ns lie in the planes z = 20, 10, 0.
PATTERNS = [tuple(Wire(n, np.array(f) * 1e-3, np.array(b) * 1e-3) for n, f, b in pattern) for pattern in FCAL2_WIRES_MM]
PARAMS = NWireSegmentationParameters()  # PLUS's defaults: 0.078 mm/px, 0.6 mm collinearity, 10 %
SPACING = PARAMS.approximate_spacing_m


def plane_points(y0_m: float, tilt_rad: float = 0.0, spacing_m: float = SPACING) -> dict[str, np.ndarray]:
    """Each wire's cut by the plane through y = ``y0_m`` (at x = 45 mm), turned by ``tilt_rad``
    about the phantom's z axis, in an MF image at ``spacing_m``: u towards −x (the first side
    wire on the right), v towards −z (the first N at the top). Solved in 3D: an oracle the
    check does not share."""
    normal = np.array([-np.sin(tilt_rad), np.cos(tilt_rad), 0.0])
    origin = np.array([0.045, y0_m, 0.0])
    across = np.array([np.cos(tilt_rad), np.sin(tilt_rad), 0.0])  # in the plane, along the Ns
    points = {}
    for pattern in PATTERNS:
        for wire in pattern:
            direction = wire.back_m - wire.front_m
            t = normal @ (origin - wire.front_m) / (normal @ direction)
            p = wire.front_m + t * direction - origin
            points[wire.name] = np.array([500.0 - (p @ across) / spacing_m, 150.0 + (0.020 - p[2]) / spacing_m])
    return points


def dots(points: dict[str, np.ndarray], bright: dict[str, float] | None = None) -> Dots:
    """The points as a frame's dot candidates, brightest first (intensity 1, or ``bright``'s)."""
    names = sorted(points, key=lambda n: -(bright or {}).get(n, 1.0))
    intensity = np.array([(bright or {}).get(n, 1.0) for n in names])
    return Dots(np.array([points[n] for n in names]), intensity, len(names))


def with_decoy(points: dict[str, np.ndarray], fraction: float) -> dict[str, np.ndarray]:
    """The points with a dot on the middle N's line at ``fraction`` of the way between its side dots."""
    a, b = points["4:G3_g3"], points["6:M3_m3"]
    return {**points, "decoy": a + fraction * (b - a)}


@pytest.mark.parametrize("y0_mm", [4.0, 20.0, 36.0])
@pytest.mark.parametrize("tilt_deg", [0.0, 12.0])
@pytest.mark.parametrize("spacing_error", [0.92, 1.0, 1.08])
def test_every_plane_through_the_phantom_fits(y0_mm, tilt_deg, spacing_error):
    points = plane_points(y0_mm * 1e-3, np.radians(tilt_deg), SPACING * spacing_error)
    geometry = nwire_geometry(PATTERNS)
    # exact dots: only the approximate spacing's error is left, 8 % against PLUS's 10 % and the dots' part
    assert phantom_misfit(points, geometry, PARAMS) < 0.5
    result = find_pattern(dots(points), geometry, PARAMS)
    assert result.points_px is not None, result.reason
    for name, uv in points.items():
        np.testing.assert_allclose(result.points_px[name], uv)


@pytest.mark.parametrize("fraction", [0.32, 0.68])
def test_a_bright_dot_where_the_diagonal_is_not_is_not_taken_for_it(fraction):
    """The plane at y = 20 mm cuts the middle N's diagonal half-way; a brighter dot at 32 % or 68 %
    of the way (too far from either side dot to pass for one) puts the cut 8 mm along the diagonal
    from where the other Ns put the plane."""
    truth = plane_points(0.020)
    candidates = dots(with_decoy(truth, fraction), {"decoy": 5.0})
    # PLUS's checks alone take the brighter dot for the diagonal's
    plus_only = find_pattern(candidates, replace(nwire_geometry(PATTERNS), patterns=()), PARAMS)
    assert plus_only.points_px is not None
    np.testing.assert_allclose(plus_only.points_px["5:H3_l3"], with_decoy(truth, fraction)["decoy"])
    # the phantom's geometry refuses it; the true pattern is found
    result = find_pattern(candidates, nwire_geometry(PATTERNS), PARAMS)
    assert result.points_px is not None, result.reason
    for name, uv in truth.items():
        np.testing.assert_allclose(result.points_px[name], uv)
    assert phantom_misfit(plus_only.points_px, nwire_geometry(PATTERNS), PARAMS) > 1.0


def test_a_frame_whose_only_pattern_fits_no_plane_is_not_segmented():
    truth = plane_points(0.020)
    wrong = with_decoy(truth, 0.95)
    wrong["5:H3_l3"] = wrong.pop("decoy")  # the true diagonal dot is not there
    result = find_pattern(dots(wrong), nwire_geometry(PATTERNS), PARAMS)
    assert result.points_px is None and result.reason == NO_FIT


def test_a_sequence_counts_a_frame_that_fits_no_plane_as_not_segmented(monkeypatch):
    """Two frames; the dots of the second put the diagonal's cut where no plane puts it."""
    truth = plane_points(0.020)
    wrong = with_decoy(truth, 0.95)
    wrong["5:H3_l3"] = wrong.pop("decoy")
    found = iter([dots(truth), dots(wrong)])
    monkeypatch.setattr("brachycal.imaging.nwire_segmentation.find_dots", lambda frame, params: next(found))
    sequence = ImageSequence(np.zeros((2, 8, 8), np.uint8), np.array([0.0, 0.1]), np.ones(2))
    result = segment_sequence(sequence, PlusConfig(PATTERNS, {}, SPACING), PARAMS, source="s.mha", poses=None)
    assert [f.ok for f in result.frames] == [True, False]
    assert result.found == 1 and result.skipped == {NO_FIT: 1}
