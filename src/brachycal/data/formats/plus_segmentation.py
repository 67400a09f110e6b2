"""PLUS fCal's segmentation settings: the ``<Segmentation>`` element of a device-set configuration.

Read into :class:`NWireSegmentationParameters` (millimetres to
metres, degrees to radians, percent to fractions). An attribute the element leaves out takes PLUS's
default (as PLUS does); one that is there must be a number in its range, or it is refused in one
line naming the file and the attribute.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

from brachycal.data.formats.plus_files import find_section, parse_xml
from brachycal.errors import InputError
from brachycal.validate import check_range, numbers_from_text

MM = 1e-3


@dataclass(frozen=True)
class NWireSegmentationParameters:
    """How to find wire dots and N patterns in B-mode frames (PLUS fCal's segmentation settings).

    Attributes:
        approximate_spacing_m: pixel size the millimetre settings are converted with, metres per pixel.
        opening_circle_radius_m: radius of the disc whose grey opening removes speckle smaller than a
            wire's dot, metres.
        opening_bar_size_m: half-length of the bars (0°, 45°, 90°, 135°) whose top-hat removes
            elongated bright structures (reverberations, phantom walls) longer than a dot, metres.
        clip_origin_px, clip_size_px: ``(u, v)`` corner and ``(width, height)`` of the image part searched;
            None searches the whole image.
        threshold_fraction: after the morphology, pixels below ``min + fraction · (max − min)`` are dropped.
        max_candidates: brightest dots kept per frame (PLUS's ``NumberOfMaximumFiducialPointCandidates``).
        collinear_distance_m: largest distance of a middle dot from the line of the two side dots, metres.
        min_theta_rad, max_theta_rad: range of a line's angle to the image's u axis (either direction).
        angle_tolerance_rad: largest angle between the lines of two Ns (they are parallel on the phantom).
        max_angle_difference_rad: PLUS's MaxAngleDifferenceDegrees (read and kept; PLUS's fCal N-wire
            labelling does not use it).
        line_pair_distance_error: relative tolerance on the distance between the lines of two Ns
            (the distances between the N planes, ±this fraction).
        max_line_shift_m: largest shift between the centres of two Ns' lines, along the lines, metres.
        use_original_intensity: score a dot by the original image around it rather than the
            processed image (PLUS's UseOriginalImageIntensityForDotIntensityScore).
    """

    approximate_spacing_m: float = 0.078e-3
    opening_circle_radius_m: float = 0.27e-3
    opening_bar_size_m: float = 2.0e-3
    clip_origin_px: tuple[int, int] | None = (27, 27)
    clip_size_px: tuple[int, int] | None = (766, 562)
    threshold_fraction: float = 0.10
    max_candidates: int = 20
    collinear_distance_m: float = 0.6e-3
    min_theta_rad: float = math.radians(-70.0)
    max_theta_rad: float = math.radians(70.0)
    angle_tolerance_rad: float = math.radians(10.0)
    max_angle_difference_rad: float = math.radians(10.0)
    line_pair_distance_error: float = 0.10
    max_line_shift_m: float = 10e-3
    use_original_intensity: bool = False

    def px(self, metres: float) -> int:
        """A length in whole pixels at the approximate spacing (rounded half up, as PLUS does)."""
        return math.floor(metres / self.approximate_spacing_m + 0.5)

    @property
    def bar_px(self) -> int:
        """Half-length of the opening bars, pixels (the bar is ``2·bar_px + 1`` long)."""
        return self.px(self.opening_bar_size_m)

    @property
    def circle_radius_px(self) -> int:
        """Radius of the opening disc, pixels."""
        return self.px(self.opening_circle_radius_m)


def read_segmentation_parameters(path: str | os.PathLike[str]) -> NWireSegmentationParameters:
    """The N-wire segmentation settings of a PLUS device-set XML (its ``<Segmentation>`` element).

    Raises:
        InputError: unreadable or unsafe XML, no ``<Segmentation>`` element, an attribute that is not
            a number in its range (a spacing or size ≤ 0, a threshold outside 0–100 %, an angle range
            that is empty or beyond ±90°), or ``ComputeSegmentationParametersFromPhantomDefinition``
            (PLUS's estimate of the angle range from a probe pose, which brachycal does not do).
    """
    path = Path(path)
    root = parse_xml(path)
    element, place = find_section(root, "Segmentation")
    if element is None:
        raise InputError(
            f"no <Segmentation> element (PLUS fCal's N-wire segmentation settings) in <{root.tag}>", file=path
        )
    defaults = NWireSegmentationParameters()

    def fail(name: str, message: str) -> InputError:
        """The refusal of one attribute, named XPath-like (as :mod:`brachycal.data.formats.plus_files` does)."""
        return InputError(f"{place}/@{name}: {message}", file=path)

    def numbers(name: str, count: int) -> list[float] | None:
        text = element.get(name)
        if text is None:
            return None
        values = numbers_from_text(text) or []
        if len(values) != count or not all(math.isfinite(v) for v in values):
            raise fail(name, f"expected {count} finite number{'s' if count > 1 else ''}, got {text!r}")
        return values

    def number(name: str, default: float, *, scale: float = 1.0, **limits: object) -> float:
        values = numbers(name, 1)
        if values is None:
            return default
        try:
            return check_range(values[0], name, **limits) * scale  # type: ignore[arg-type]
        except InputError as exc:
            raise fail(name, exc.problem) from None

    def whole(name: str, count: int, low: int) -> tuple[int, ...] | None:
        values = numbers(name, count)
        if values is None:
            return None
        if not all(v == int(v) and v >= low for v in values):
            raise fail(
                name, f"expected {count} whole number{'s' if count > 1 else ''} ≥ {low}, got {element.get(name)!r}"
            )
        return tuple(int(v) for v in values)

    if element.get("ComputeSegmentationParametersFromPhantomDefinition", "0").strip() not in ("0", ""):
        raise fail(
            "ComputeSegmentationParametersFromPhantomDefinition",
            "computing the segmentation settings from the phantom definition is not supported: "
            "give MinThetaDegrees and MaxThetaDegrees",
        )
    spacing = number("ApproximateSpacingMmPerPixel", defaults.approximate_spacing_m, scale=MM, low=0.0, low_open=True)
    origin = whole("ClipRectangleOrigin", 2, 0)
    size = whole("ClipRectangleSize", 2, 1)
    if (origin is None) != (size is None):
        missing = "ClipRectangleSize" if size is None else "ClipRectangleOrigin"
        raise fail(missing, "the clip rectangle needs both its origin and its size")
    candidates = whole("NumberOfMaximumFiducialPointCandidates", 1, 1)
    min_theta = number("MinThetaDegrees", math.degrees(defaults.min_theta_rad), low=-90.0, high=90.0)
    max_theta = number("MaxThetaDegrees", math.degrees(defaults.max_theta_rad), low=-90.0, high=90.0)
    if not min_theta < max_theta:
        raise fail("MaxThetaDegrees", f"must be above MinThetaDegrees ({min_theta:g}), got {max_theta:g}")
    use_original = element.get("UseOriginalImageIntensityForDotIntensityScore", "FALSE").strip().upper()
    if use_original not in ("TRUE", "FALSE"):
        raise fail("UseOriginalImageIntensityForDotIntensityScore", f"expected TRUE or FALSE, got {use_original!r}")
    return NWireSegmentationParameters(
        approximate_spacing_m=spacing,
        opening_circle_radius_m=number(
            "MorphologicalOpeningCircleRadiusMm", defaults.opening_circle_radius_m, scale=MM, low=0.0
        ),
        opening_bar_size_m=number(
            "MorphologicalOpeningBarSizeMm", defaults.opening_bar_size_m, scale=MM, low=0.0, low_open=True
        ),
        # no clip rectangle: the whole image (PLUS: "Using the largest ROI possible"), not fCal 2.0's
        clip_origin_px=(origin[0], origin[1]) if origin is not None else None,
        clip_size_px=(size[0], size[1]) if size is not None else None,
        threshold_fraction=number(
            "ThresholdImagePercent", defaults.threshold_fraction, scale=0.01, low=0.0, high=100.0, unit="%"
        ),
        max_candidates=candidates[0] if candidates is not None else defaults.max_candidates,
        collinear_distance_m=number(
            "CollinearPointsMaxDistanceFromLineMm", defaults.collinear_distance_m, scale=MM, low=0.0, low_open=True
        ),
        min_theta_rad=math.radians(min_theta),
        max_theta_rad=math.radians(max_theta),
        angle_tolerance_rad=number(
            "AngleToleranceDegrees", defaults.angle_tolerance_rad, scale=math.pi / 180, low=0.0, high=90.0
        ),
        max_angle_difference_rad=number(
            "MaxAngleDifferenceDegrees", defaults.max_angle_difference_rad, scale=math.pi / 180, low=0.0, high=90.0
        ),
        line_pair_distance_error=number(
            "MaxLinePairDistanceErrorPercent", defaults.line_pair_distance_error, scale=0.01, low=0.0, high=100.0
        ),
        max_line_shift_m=number("MaxLineShiftMm", defaults.max_line_shift_m, scale=MM, low=0.0),
        use_original_intensity=use_original == "TRUE",
    )
