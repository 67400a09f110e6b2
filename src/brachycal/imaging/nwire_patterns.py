"""N patterns among a frame's wire dots: which dot is which wire of the phantom.

An image plane crossing an N-wire phantom shows each N as three collinear dots: the two side wires
at the N's side-to-side distance (or more, the plane being tilted) with the diagonal wire's dot
between them. The Ns of a phantom lie in parallel planes, so their lines are parallel in the image,
at the planes' distances. The search follows PLUS's fCal (``PlusFidLineFinder``, ``PlusFidLabeling``):

1. lines: two dots at the side-to-side distance (± :data:`~brachycal.imaging.nwire_parameters.
   SIDE_DISTANCE_TOLERANCE_M`) along a direction within the allowed angle range, and a third dot
   within ``collinear_distance_m`` of their line, between them (± :data:`~brachycal.imaging.
   nwire_parameters.MIDDLE_DISTANCE_TOLERANCE_M` from the expected place); a line's score is the
   sum of its dots' scores;
2. pattern: one line per N, no dot used twice, every two lines parallel within
   ``angle_tolerance_rad``, apart by the N planes' distance (± ``line_pair_distance_error``) and
   shifted along each other by at most ``max_line_shift_m``;
3. labels (as PLUS, for its ``MF`` image orientation): lines from the top of the image down are the
   configuration's Ns in file order; along each line, dots from right (largest u) to left are its
   wires in file order. Images of another orientation (``UF``, ``MN``, ``UN``) are labelled as their
   ``MF`` mirror image would be;
4. the phantom's geometry (beyond PLUS's checks): the distances between the Ns' diagonal cuts
   (:func:`middle_point_phantom`) are those between their middle dots (:func:`phantom_misfit`);
   of the labelled sets that fit, the brightest is the frame's pattern.

Frames where no pattern passes are reported with the reason, never guessed.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from brachycal.data.formats.plus_files import Wire
from brachycal.errors import InputError
from brachycal.imaging.nwire_dots import Dots
from brachycal.imaging.nwire_parameters import (
    MIDDLE_DISTANCE_TOLERANCE_M,
    SIDE_DISTANCE_TOLERANCE_M,
    NWireSegmentationParameters,
)
from brachycal.se3 import FloatArray

#: Why a frame has no pattern (the counts of a sequence's skipped frames are keyed by these).
TOO_FEW_DOTS = "fewer dots than wires"
NO_LINES = "fewer N-shaped lines than Ns"
NO_PATTERN = "no set of lines with the phantom's spacing"
NO_FIT = "no set of lines fits the phantom's wire layout"
#: PLUS's ultrasound image orientations (``UltrasoundImageOrientation``, first two letters): u grows
#: towards the probe's Marked or Unmarked side, v towards the Far side (the transducer at the top)
#: or the Near side. PLUS's fCal segments MF images; the others are MF mirrored.
ORIENTATIONS = ("MF", "UF", "MN", "UN")


@dataclass(frozen=True)
class NWireGeometry:
    """What the search needs of a phantom's Ns, metres and radians.

    Attributes:
        wire_names: per N, its three wire names (side, diagonal, side) in the configuration's order.
        side_distance_m: per N, the distance between its two (parallel) side wires.
        middle_distance_m: per N, where the diagonal's middle lies from the first side wire, along
            the N (PLUS's expected place of the middle dot).
        plane_distance_m: ``(min, max)`` distance between the planes of two Ns (0, 0 for one N).
        plane_angle_rad: ``(min, max)`` angle between the planes of two Ns (0, 0 if parallel).
        patterns: the Ns' wires (first side, diagonal, second side), phantom frame, metres: what
            the geometry check (step 4) compares with; empty: no such check.
    """

    wire_names: tuple[tuple[str, str, str], ...]
    side_distance_m: tuple[float, ...]
    middle_distance_m: tuple[float, ...]
    plane_distance_m: tuple[float, float]
    plane_angle_rad: tuple[float, float]
    patterns: tuple[tuple[Wire, Wire, Wire], ...] = ()


def nwire_geometry(patterns: Sequence[tuple[Wire, Wire, Wire]]) -> NWireGeometry:
    """The image-side geometry of a phantom's N patterns (end points in the phantom frame, metres)."""
    names, sides, middles, planes = [], [], [], []
    for first, diagonal, last in patterns:
        along = first.back_m - first.front_m
        along = along / np.linalg.norm(along)
        across = last.front_m - first.front_m
        across = across - along * (across @ along)  # perpendicular between the parallel side wires
        side = float(np.linalg.norm(across))
        middle = 0.5 * (diagonal.front_m + diagonal.back_m) - first.front_m
        names.append((first.name, diagonal.name, last.name))
        sides.append(side)
        middles.append(float(abs(middle @ across) / side))
        normal = np.cross(along, across)
        planes.append((normal / np.linalg.norm(normal), first.front_m))
    distances, angles = [], []
    for (n1, o1), (n2, o2) in itertools.combinations(planes, 2):
        distances.append(float(abs(n1 @ (o2 - o1))))
        angles.append(float(np.arccos(min(1.0, abs(float(n1 @ n2))))))
    return NWireGeometry(
        tuple(names),
        tuple(sides),
        tuple(middles),
        (min(distances), max(distances)) if distances else (0.0, 0.0),
        (min(angles), max(angles)) if angles else (0.0, 0.0),
        tuple((first, diagonal, last) for first, diagonal, last in patterns),
    )


def _closest_point_on_first(a0: FloatArray, a1: FloatArray, b0: FloatArray, b1: FloatArray) -> FloatArray:
    """Point of line a (through a0, a1) closest to line b (through b0, b1)."""
    u, v, w = a1 - a0, b1 - b0, a0 - b0
    denominator = (u @ u) * (v @ v) - (u @ v) ** 2
    if denominator < 1e-24:
        raise InputError("an N-wire's side wire is parallel to its diagonal: not an N pattern")
    s = ((u @ v) * (v @ w) - (v @ v) * (u @ w)) / denominator
    return a0 + s * u


def middle_point_phantom(
    pattern: tuple[Wire, Wire, Wire], p1_px: ArrayLike, p2_px: ArrayLike, p3_px: ArrayLike
) -> FloatArray:
    """Where the image plane cuts the diagonal wire, in the phantom frame, metres ``(3,)``.

    Args:
        pattern: (first side wire, diagonal wire, second side wire).
        p1_px, p2_px, p3_px: their segmented intersections in the image, pixels ``(2,)``.
    """
    w1, w2, w3 = pattern
    w12 = _closest_point_on_first(w1.front_m, w1.back_m, w2.front_m, w2.back_m)
    w32 = _closest_point_on_first(w3.front_m, w3.back_m, w2.front_m, w2.back_m)
    p1, p2, p3 = (np.asarray(p, dtype=float) for p in (p1_px, p2_px, p3_px))
    span = np.linalg.norm(p3 - p1)
    if not span > 0.0:  # the ratio would be 0/0: no position along the diagonal wire
        raise InputError(f"the outer wires {w1.name!r} and {w3.name!r} are segmented at the same pixel")
    return w12 + (np.linalg.norm(p2 - p1) / span) * (w32 - w12)


def phantom_misfit(
    points_px: dict[str, FloatArray], geometry: NWireGeometry, params: NWireSegmentationParameters
) -> float:
    """How far a labelled pattern is from one plane through the phantom: the largest, over pairs of
    Ns, of ``|d_image − d_phantom| / tolerance`` (1 at the tolerance; 0 with fewer than two Ns).

    ``d_phantom`` is the distance between the two Ns' middle points (:func:`middle_point_phantom`),
    ``d_image`` that between their middle dots at the approximate spacing. For a true pattern they
    differ by the spacing's error and by the dots' errors. PLUS bounds the first for distances
    between Ns by ``line_pair_distance_error`` (a fraction of ``d_phantom``), and a dot's distance
    from its line by ``collinear_distance_m`` (δ): taken as the bound of each dot's error, it moves
    ``d_image`` by δ√2 (two dots) and an N's middle point by its diagonal's length ``L`` times the
    ratio's error, ``δ √(1 + (1 − t)² + t²) / c`` (the ratio ``t = |p1p2| / |p1p3|``, ``c`` the
    side dots' distance), the dots' errors combined in quadrature. The tolerance is the spacing's
    part plus the quadrature sum of the dots' parts.
    """
    delta = params.collinear_distance_m
    middles, reach = [], []
    for pattern, names in zip(geometry.patterns, geometry.wire_names, strict=True):
        p1, p2, p3 = (np.asarray(points_px[name], dtype=float) for name in names)
        middles.append((p2, middle_point_phantom(pattern, p1, p2, p3)))
        t = float(np.linalg.norm(p2 - p1) / np.linalg.norm(p3 - p1))
        c = float(np.linalg.norm(p3 - p1)) * params.approximate_spacing_m
        diagonal = float(np.linalg.norm(pattern[1].back_m - pattern[1].front_m))
        reach.append(diagonal * delta * math.sqrt(1.0 + (1.0 - t) ** 2 + t**2) / c)
    worst = 0.0
    for (i, (m_i, M_i)), (j, (m_j, M_j)) in itertools.combinations(enumerate(middles), 2):
        d_phantom = float(np.linalg.norm(M_i - M_j))
        d_image = float(np.linalg.norm(m_i - m_j)) * params.approximate_spacing_m
        dots = math.sqrt(2.0 * delta**2 + reach[i] ** 2 + reach[j] ** 2)
        worst = max(worst, abs(d_image - d_phantom) / (params.line_pair_distance_error * d_phantom + dots))
    return worst


@dataclass(frozen=True)
class _Line:
    dots: tuple[int, int, int]  # start (largest u), middle, end
    score: float
    start: FloatArray
    end: FloatArray
    direction: FloatArray  # unit, start → end


@dataclass(frozen=True)
class PatternResult:
    """The N pattern of one frame: wire name → ``(u, v)`` pixel, or the reason none was found."""

    points_px: dict[str, FloatArray] | None
    reason: str | None = None
    score: float = 0.0


def _angle_ok(angle: float, params: NWireSegmentationParameters) -> bool:
    """A direction's angle to the u axis lies in [min θ, max θ], either way along the line."""
    for candidate in (angle, angle - math.pi, angle + math.pi):
        if params.min_theta_rad < candidate < params.max_theta_rad:
            return True
    return False


def _lines(dots: Dots, geometry: NWireGeometry, params: NWireSegmentationParameters, orientation: str) -> list[_Line]:
    uv = dots.uv_px
    collinear_px = params.collinear_distance_m / params.approximate_spacing_m
    side_tolerance_px = SIDE_DISTANCE_TOLERANCE_M / params.approximate_spacing_m
    middle_tolerance_px = MIDDLE_DISTANCE_TOLERANCE_M / params.approximate_spacing_m
    found: dict[tuple[int, int, int], _Line] = {}
    for i, j in itertools.combinations(range(len(uv)), 2):
        start, end = (i, j) if uv[i, 0] >= uv[j, 0] else (j, i)
        vector = uv[end] - uv[start]
        length = float(np.hypot(*vector))
        if length == 0.0 or not _angle_ok(math.atan2(vector[1], vector[0]), params):
            continue
        direction = vector / length
        for side_m, middle_m in zip(geometry.side_distance_m, geometry.middle_distance_m, strict=True):
            if abs(length - side_m / params.approximate_spacing_m) >= side_tolerance_px:
                continue
            offset = uv - uv[start]
            along = offset @ direction
            across = np.abs(offset @ np.array([-direction[1], direction[0]]))
            # the start (largest u) is the first side wire in an M image, the last one in a U image
            from_start_m = middle_m if orientation[0] == "M" else side_m - middle_m
            middle_px = from_start_m / params.approximate_spacing_m
            ok = (
                (across <= collinear_px)
                & (along >= 0.0)
                & (along <= length)  # between the side dots
                & (np.abs(np.hypot(offset[:, 0], offset[:, 1]) - middle_px) < middle_tolerance_px)
            )
            ok[[start, end]] = False
            for k in np.flatnonzero(ok):
                key = (start, int(k), end)
                if key not in found:
                    score = float(dots.intensity[[start, int(k), end]].sum())
                    found[key] = _Line(key, score, uv[start], uv[end], direction)
    return sorted(found.values(), key=lambda line: -line.score)


def _compatible(a: _Line, b: _Line, geometry: NWireGeometry, params: NWireSegmentationParameters) -> bool:
    """Whether two lines can be two Ns of the phantom (PLUS's pairwise test, ``PlusFidLabeling``)."""
    if set(a.dots) & set(b.dots):
        return False
    angle = math.acos(min(1.0, abs(float(a.direction @ b.direction))))
    if angle < params.angle_tolerance_rad:
        normal = np.array([-b.direction[1], b.direction[0]])
        distance_px = abs(float((a.start - b.start) @ normal))
        low = geometry.plane_distance_m[0] * (1.0 - params.line_pair_distance_error)
        high = geometry.plane_distance_m[1] * (1.0 + params.line_pair_distance_error)
        if not low / params.approximate_spacing_m <= distance_px <= high / params.approximate_spacing_m:
            return False
        shift_px = float((0.5 * (b.start + b.end) - 0.5 * (a.start + a.end)) @ a.direction)
        return abs(shift_px) <= params.max_line_shift_m / params.approximate_spacing_m
    low = geometry.plane_angle_rad[0] - params.angle_tolerance_rad
    high = geometry.plane_angle_rad[1] + params.angle_tolerance_rad
    return low <= angle <= high


def find_pattern(
    dots: Dots, geometry: NWireGeometry, params: NWireSegmentationParameters, *, orientation: str = "MF"
) -> PatternResult:
    """Label a frame's dots with the phantom's wires (see the module's steps), or say why not.

    Args:
        orientation: the image's ultrasound orientation (PLUS's two letters, see :data:`ORIENTATIONS`):
            the labels of step 3 are PLUS's for ``MF``; a ``U`` image is mirrored along u (its first
            wire on the left), an ``N`` image along v (its first N at the bottom).
    """
    if orientation not in ORIENTATIONS:
        raise ValueError(f"orientation must be one of {', '.join(ORIENTATIONS)}, got {orientation!r}")
    count = len(geometry.wire_names)
    if len(dots.uv_px) < 3 * count:
        return PatternResult(None, TOO_FEW_DOTS)
    lines = _lines(dots, geometry, params, orientation)
    if len(lines) < count:
        return PatternResult(None, NO_LINES)
    fits = np.array([[_compatible(a, b, geometry, params) for b in lines] for a in lines])
    scores = np.array([line.score for line in lines])
    best: tuple[float, dict[str, FloatArray]] | None = None
    sets = 0
    # sets of `count` pairwise compatible lines (cliques), grown from candidates compatible with all so far
    stack: list[tuple[tuple[int, ...], np.ndarray]] = [((), np.arange(len(lines)))]
    while stack:
        chosen, candidates = stack.pop()
        if len(chosen) == count:
            sets += 1
            score = float(scores[list(chosen)].sum())
            if best is None or score > best[0]:
                points = _labelled([lines[k] for k in chosen], dots, geometry, orientation)
                if not geometry.patterns or phantom_misfit(points, geometry, params) <= 1.0:
                    best = (score, points)
            continue
        for position, k in enumerate(candidates):
            rest = candidates[position + 1 :]
            stack.append(((*chosen, int(k)), rest[fits[k, rest]]))
    if best is None:
        return PatternResult(None, NO_FIT if sets else NO_PATTERN)
    return PatternResult(best[1], None, best[0])


def _labelled(chosen: list[_Line], dots: Dots, geometry: NWireGeometry, orientation: str) -> dict[str, FloatArray]:
    """Wire name → pixel of one line per N (step 3 of the module)."""
    down = 1.0 if orientation[1] == "F" else -1.0  # F: the first N nearest the transducer (top)
    left = 1.0 if orientation[0] == "M" else -1.0  # M: the first wire on the marked side (right)
    ordered_lines = sorted(chosen, key=lambda line: down * float(line.start[1] + line.end[1]))
    points: dict[str, FloatArray] = {}
    for names, line in zip(geometry.wire_names, ordered_lines, strict=True):
        ordered = sorted(line.dots, key=lambda k: -left * float(dots.uv_px[k, 0]))
        for name, k in zip(names, ordered, strict=True):
            points[name] = dots.uv_px[k].copy()
    return points
