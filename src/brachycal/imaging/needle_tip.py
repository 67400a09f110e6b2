"""Needle tip in a B-mode frame: a proposed annotation, sub-pixel, with a confidence in [0, 1].

:func:`detect_tip` works on one 8-bit frame ``(H, W)`` (``frame[v, u]``), in pixels of the image
frame (``u`` along columns, ``v`` along rows, the origin at the centre of pixel (0, 0)).

Design: ``docs/design/image_analysis.md``, "The needle tip in a B-mode frame".
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from brachycal.errors import InputError
from brachycal.se3 import FloatArray

__all__ = [
    "AGREEMENT_PX",
    "BACKGROUND_PX",
    "EDGE_RATIO_SCALE",
    "FALSE_ALARM_Z",
    "MAX_EDGE_RATIO",
    "MIN_CONFIDENCE",
    "MIN_ELONGATION",
    "PEAK_PX",
    "SHAFT_RADIUS_PX",
    "SHAFT_WIDTH_PX",
    "SMOOTH_SD_PX",
    "TipDetection",
    "detect_tip",
    "detect_tips",
]

#: Smoothing of the frame before the search, SD in pixels: about the tip echo's own size (the
#: PSF widened by the needle's radius, SD ≈ 2–2.5 px), the matched filter of a blob, so that single
#: speckle grains (0.35 × 0.8 mm FWHM, 2 × 4 px) are averaged down (on the twin 2.5 px gave the
#: smallest error of 1.5–3 px).
SMOOTH_SD_PX = 2.5
#: Side of the square over which the local speckle mean and SD are taken, pixels (11 mm): many
#: speckle grains, much more than the tip's echo, less than the depth over which the gain changes.
BACKGROUND_PX = 61
#: Half-side of the window of the sub-pixel peak, pixels.
PEAK_PX = 5
#: Radius around the peak searched for the shaft's streak, pixels (7.6 mm).
SHAFT_RADIUS_PX = 40
#: Largest RMS distance of the streak from its axis that is still a needle, pixels: the shaft's
#: echo is the PSF widened by the 18 G needle's radius (SD ≈ 1.2 px) plus the smoothing.
SHAFT_WIDTH_PX = 2.5
#: Streak elongation (ratio of its principal SDs) below which its axis is not trusted.
MIN_ELONGATION = 1.5
#: Scale of the agreement between the peak and the end of the echo, pixels (about the PSF's SD:
#: a peak within it of the end is the tip's own echo).
AGREEMENT_PX = 2.0
#: Largest contrast (speckle SDs) that speckle alone reaches in a 1080×720 frame of the
#: twin: 4.96 over 100 needle-free frames (seeds 0–3, ``benchmarks/needle_tip.py``), rounded up
#: with a margin. The twin's tips stand at 17–21.
FALSE_ALARM_Z = 6.0
#: Largest ratio of the echo's fall-off length beyond its end (SD of the Gaussian edge along the
#: shaft) to its width across the shaft (SD) for a tip in the plane. A tip's echo ends within the
#: PSF: along depth the axial PSF is the narrower (ratio 0.55–0.93 on the twin's in-plane tips); a
#: tip in front of the plane leaves only the shaft crossing the beam, whose echo fades over the
#: beam's thickness seen along the needle (ratio 1.2–2.0 for tips 1.5–2.5 mm off the plane).
#: Calibrated for needles crossing the plane along depth (the paper's set-up); a needle lying in
#: the plane along u would need ~1.3.
MAX_EDGE_RATIO = 1.0
#: Scale of the sharpness factor: at 0.2 above :data:`MAX_EDGE_RATIO` the factor is 0.61, at 0.5 0.04.
EDGE_RATIO_SCALE = 0.2
#: Frames below this confidence are listed for a person to annotate. From the twin's stress set
#: (``benchmarks/needle_tip.py``: 256 frames with the tip 0–3 mm off the plane), the lowest
#: threshold above which the detections' 95th-percentile error stays within a person's (2.45 px
#: for 1 px SD per axis): at or above 0.7 the p95 is 0.68 px; below 0.5 the median errors are
#: 17–32 px (the shaft crossing the plane, not the tip).
MIN_CONFIDENCE = 0.5

#: SD of a 2D Gaussian cut at half its height, in its own SDs (along any axis).
_CUT_GAUSSIAN_SD = 0.466
#: Where a Gaussian falls to 3/4 and to 1/4 of its height, in its SDs from the centre.
_Z_THREE_QUARTERS = float(np.sqrt(2.0 * np.log(4.0 / 3.0)))
_Z_QUARTER = float(np.sqrt(2.0 * np.log(4.0)))


def _crossing(s: FloatArray, profile: FloatArray, start: int, level: float) -> float:
    """First ``s`` beyond ``start`` where ``profile`` falls below ``level`` (linear between samples;
    the profile's end if it never does)."""
    below = np.flatnonzero(profile[start:] < level)
    if not len(below):
        return float(s[-1])
    k = start + int(below[0])
    if k == start:
        return float(s[k])
    return float(s[k - 1] + (profile[k - 1] - level) / (profile[k - 1] - profile[k]) * (s[k] - s[k - 1]))


@dataclass(frozen=True)
class TipDetection:
    """A proposed tip annotation.

    Attributes:
        uv_px: ``(2,)`` the tip, pixels (sub-pixel), or NaN when the frame holds no imaged pixel.
        confidence: in [0, 1], the product of the four factors below.
        contrast: the peak's contrast, in local speckle SDs.
        contrast_factor, line_factor, agreement_factor, sharpness_factor: the confidence's factors
            (module docstring).
        axis: ``(2,)`` unit shaft direction towards the tip, pixels' axes ``(u, v)``.
        residual_px: RMS distance of the streak's pixels from the shaft's axis.
        shift_px: from the peak to the echo's end (the tip) along the axis, pixels.
        edge_ratio: the echo's fall-off length beyond its end over its width across the shaft.
    """

    uv_px: FloatArray
    confidence: float
    contrast: float
    contrast_factor: float
    line_factor: float
    agreement_factor: float
    sharpness_factor: float
    axis: FloatArray
    residual_px: float
    shift_px: float
    edge_ratio: float = float("nan")


def _contrast_map(frame: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Smoothed frame ``S``, local mean, local SD and the mask of imaged pixels, all ``(H, W)``."""
    from scipy.ndimage import gaussian_filter, uniform_filter  # lazy: start-up (scipy)

    f = frame.astype(np.float32)
    imaged = (f > 0).astype(np.float32)
    smooth = gaussian_filter(f, SMOOTH_SD_PX, mode="nearest")
    cover = uniform_filter(imaged, BACKGROUND_PX, mode="constant")
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = uniform_filter(smooth * imaged, BACKGROUND_PX, mode="constant") / cover
        second = uniform_filter(smooth * smooth * imaged, BACKGROUND_PX, mode="constant") / cover
    # A flat background would make any echo infinitely contrasted: the SD is floored at one grey
    # level (the 8-bit quantisation's own SD is 0.29).
    sd = np.sqrt(np.maximum(second - mean * mean, 1.0))
    inside = (uniform_filter(imaged, 2 * PEAK_PX + 1, mode="constant") > 0.999) & (cover > 0.25)
    return smooth, np.nan_to_num(mean), sd, inside


def _bilinear(image: np.ndarray, u: FloatArray, v: FloatArray) -> FloatArray:
    from scipy.ndimage import map_coordinates  # lazy: start-up (scipy)

    return map_coordinates(image, [v, u], order=1, mode="nearest")


def detect_tip(frame: ArrayLike, prior_direction: ArrayLike | None = None) -> TipDetection:
    """Propose the needle tip of one B-mode frame (the module docstring gives the method).

    Args:
        frame: ``(H, W)`` single-channel frame (``frame[v, u]``), 8-bit grey (any real type is
            taken as grey levels).
        prior_direction: ``(2,)`` the expected shaft direction towards the tip in pixel axes
            ``(u, v)`` (need not be unit), or ``None``.

    Raises:
        InputError: a frame that is not 2D, or a prior direction that is not two finite numbers, not zero.
    """
    image = np.asarray(frame)
    if image.ndim != 2 or min(image.shape) < 2 * PEAK_PX + 1:
        raise InputError(f"a frame must be a 2D grey image of at least {2 * PEAK_PX + 1} px a side, got {image.shape}")
    prior = None
    if prior_direction is not None:
        prior = np.asarray(prior_direction, dtype=float).reshape(-1)
        if prior.shape != (2,) or not np.all(np.isfinite(prior)) or np.linalg.norm(prior) == 0:
            raise InputError(f"the expected needle direction must be two finite numbers, not both 0, got {prior}")
        prior = prior / np.linalg.norm(prior)
    smooth, mean, sd, inside = _contrast_map(image)
    if not np.any(inside):
        nan = np.full(2, np.nan)
        return TipDetection(nan, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, nan, float("nan"), 0.0)
    # Log compression turns the depth's gain into an offset: speckle has the same SD at every depth
    # (5.6 dB for fully developed speckle). One SD for the frame — the median of the local ones —
    # is not inflated by the needle's own echo and shadow, as the SD around the needle is.
    z = np.where(inside, (smooth - mean) / float(np.median(sd[inside])), -np.inf)
    v_peak, u_peak = (int(i) for i in np.unravel_index(int(np.argmax(z)), z.shape))
    contrast = float(z[v_peak, u_peak])
    height, width = image.shape

    # Sub-pixel peak: centroid of the brightness above half the peak's height over the background.
    va, vb = max(v_peak - PEAK_PX, 0), min(v_peak + PEAK_PX + 1, height)
    ua, ub = max(u_peak - PEAK_PX, 0), min(u_peak + PEAK_PX + 1, width)
    background = float(mean[v_peak, u_peak])
    top = float(smooth[v_peak, u_peak])
    half = background + 0.5 * (top - background)
    w = np.clip(smooth[va:vb, ua:ub] - half, 0.0, None)
    vv, uu = np.mgrid[va:vb, ua:ub]
    total = float(w.sum())
    peak = (
        np.array([(w * uu).sum() / total, (w * vv).sum() / total]) if total > 0 else np.array([u_peak, v_peak], float)
    )

    # The shaft: the streak connected to the peak, above half its contrast, within the radius.
    from scipy.ndimage import label  # lazy: start-up (scipy)

    r = SHAFT_RADIUS_PX
    ra, rb = max(v_peak - r, 0), min(v_peak + r + 1, height)
    ca, cb = max(u_peak - r, 0), min(u_peak + r + 1, width)
    patch = z[ra:rb, ca:cb]
    labels, _ = label(patch > 0.5 * contrast)
    streak = labels == labels[v_peak - ra, u_peak - ca]
    sv, su = np.nonzero(streak)
    weight = np.clip(smooth[ra:rb, ca:cb][streak] - background, 1e-6, None)
    points = np.column_stack([su + ca, sv + ra]).astype(float)
    centre = (weight[:, None] * points).sum(axis=0) / weight.sum()
    spread = ((weight[:, None, None] * np.einsum("ni,nj->nij", points - centre, points - centre)).sum(axis=0)) / (
        weight.sum()
    )
    eigenvalues, eigenvectors = np.linalg.eigh(spread)
    axis = eigenvectors[:, 1]
    elongation = float(np.sqrt(eigenvalues[1] / max(eigenvalues[0], 1e-9)))
    if prior is not None and elongation < MIN_ELONGATION:
        axis = prior
    elif prior is not None:
        axis = axis if axis @ prior >= 0 else -axis
    elif (peak - centre) @ axis < 0:  # towards the peak: the tip is the streak's bright end
        axis = -axis
    normal = np.array([-axis[1], axis[0]])
    residual = float(np.sqrt((weight * ((points - centre) @ normal) ** 2).sum() / weight.sum()))

    # The echo's leading edge: beyond its end only the blur of the tip's echo is left, a Gaussian
    # tail. The profile along the axis (averaged over 3 parallel lines, 1 px apart) crosses 3/4 and
    # 1/4 of the peak's height over the background at s0 + 0.76 σ and s0 + 1.67 σ: two crossings
    # give the end s0 and σ. The peak itself sits s0 − s_max behind the end when the shaft's echo
    # adds to it (or far behind when the brightest point is mid-shaft).
    s = np.arange(-PEAK_PX, SHAFT_RADIUS_PX, 0.25)
    profile = np.mean(
        [
            _bilinear(smooth, peak[0] + s * axis[0] + o * normal[0], peak[1] + s * axis[1] + o * normal[1])
            for o in (-1, 0, 1)
        ],
        axis=0,
    )
    near = np.flatnonzero(np.abs(s) <= PEAK_PX / 2)
    k_max = int(near[np.argmax(profile[near])])
    top = float(profile[k_max])
    s_hi = _crossing(s, profile, k_max, background + 0.75 * (top - background))
    s_lo = _crossing(s, profile, k_max, background + 0.25 * (top - background))
    sigma = (s_lo - s_hi) / (_Z_QUARTER - _Z_THREE_QUARTERS)
    s_end = s_hi - _Z_THREE_QUARTERS * sigma
    shift = float(s_end - s[k_max])
    tip = peak + s_end * axis
    # The echo's width across the shaft, from the peak's spread above half height (a Gaussian cut at
    # half its height keeps 0.466 of its SD in its second moment).
    across = ((uu - peak[0]) * normal[0] + (vv - peak[1]) * normal[1]) ** 2
    sigma_across = float(np.sqrt((w * across).sum() / max(total, 1e-9))) / _CUT_GAUSSIAN_SD
    edge_ratio = float(sigma / max(sigma_across, 1e-9))

    contrast_factor = float(1.0 - np.exp(-(max(contrast - FALSE_ALARM_Z, 0.0) ** 2)))
    line_factor = float(np.exp(-0.5 * (max(residual - SHAFT_WIDTH_PX, 0.0) / SHAFT_WIDTH_PX) ** 2))
    agreement_factor = float(np.exp(-0.5 * (abs(shift) / AGREEMENT_PX) ** 2))
    sharpness_factor = float(np.exp(-0.5 * (max(edge_ratio - MAX_EDGE_RATIO, 0.0) / EDGE_RATIO_SCALE) ** 2))
    confidence = contrast_factor * line_factor * agreement_factor * sharpness_factor
    return TipDetection(
        uv_px=tip,
        confidence=confidence,
        contrast=contrast,
        contrast_factor=contrast_factor,
        line_factor=line_factor,
        agreement_factor=agreement_factor,
        sharpness_factor=sharpness_factor,
        axis=axis,
        residual_px=residual,
        shift_px=shift,
        edge_ratio=edge_ratio,
    )


def detect_tips(
    frames: ArrayLike, prior_direction: ArrayLike | None = None, *, progress: Callable[[int], None] | None = None
) -> list[TipDetection]:
    """:func:`detect_tip` on each frame of ``(N, H, W)``; ``progress(1)`` after each frame."""
    stack = np.asarray(frames)
    if stack.ndim != 3:
        raise InputError(f"frames must be (N, H, W), got shape {stack.shape}")
    detections = []
    for frame in stack:
        detections.append(detect_tip(frame, prior_direction))
        if progress is not None:
            progress(1)
    return detections
