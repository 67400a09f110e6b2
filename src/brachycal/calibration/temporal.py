"""Temporal calibration: the lag between two time-stamped streams that see the same motion.

``lag_s`` (seconds) follows PLUS's ``TrackerLagSec``: positive when the moving stream's (tracker's
or robot's) timestamps are late; add it to the video's times to bring them onto its clock.

Design: ``docs/design/temporal.md``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from brachycal._lazy import renamed
from brachycal.data.formats.metaimage import read_image_sequence, read_sequence_header
from brachycal.data.formats.plus_files import sequence_transform
from brachycal.data.formats.plus_temporal import PlusTemporalSettings, read_plus_temporal_settings
from brachycal.errors import DegenerateDataError, InputError
from brachycal.imaging.tank_line import find_tank_line
from brachycal.se3 import FloatArray

if TYPE_CHECKING:
    from brachycal.imaging.tank_line import TankLineTrack

#: PLUS's default search range (``MaximumMovingLagSec``), seconds.
DEFAULT_MAX_LAG_S = 0.5
#: PLUS's default sampling resolution of the lag search, seconds.
DEFAULT_RESOLUTION_S = 0.001
#: Fewest fixed samples in the overlap: the regression has 3 parameters and the residual
#: autocorrelation needs a few more; below 10 the SD itself is not trustworthy.
MIN_SAMPLES = 10
#: The lag must be determined within the search: refused when ``DETERMINED_SD × sd_s`` (a 95 %
#: interval's half-width) exceeds ``max_lag_s``. Signals without shared motion (noise against
#: motion, or motion too small for the noise) give a flat correlation and a large propagated SD.
DETERMINED_SD = 2.0
#: Lags scanned per block (memory: block × fixed samples doubles).
_BLOCK = 256


@dataclass(frozen=True)
class LagEstimate:
    """The lag of the moving stream b behind the fixed stream a.

    Attributes:
        lag_s: seconds; b's stamp of an instant minus a's (positive: b's timestamps are late).
        sd_s: standard deviation of ``lag_s``, seconds (Gauss–Newton, residual autocorrelation
            accounted for; see the module docstring).
        correlation: Pearson correlation of the aligned signals (of b inverted if ``inverted``).
        inverted: whether the moving signal was inverted to align (``allow_inverted``).
        n_samples: fixed samples used.
        n_effective: effective independent samples, ``n (1−ρ)/(1+ρ)``.
        residual_sd: SD of the alignment residual, in the fixed signal's unit.
        scale: ``β``, fixed-signal units per moving-signal unit (negative if ``inverted``).
        lags_s: ``(K,)`` lags searched, seconds.
        correlations: ``(K,)`` correlation at each lag searched (for b as aligned).
    """

    lag_s: float
    sd_s: float
    correlation: float
    inverted: bool
    n_samples: int
    n_effective: float
    residual_sd: float
    scale: float
    lags_s: FloatArray = field(repr=False)
    correlations: FloatArray = field(repr=False)

    def as_dict(self) -> dict[str, object]:
        """JSON-ready summary (seconds; without the correlation curve)."""
        return {
            "lag_s": self.lag_s,
            "sd_s": self.sd_s,
            "correlation": self.correlation,
            "inverted": self.inverted,
            "n_samples": self.n_samples,
            "n_effective": self.n_effective,
            "residual_sd": self.residual_sd,
            "scale": self.scale,
        }


def _signal(t: ArrayLike, x: ArrayLike, name: str) -> tuple[FloatArray, FloatArray]:
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    if t.ndim != 1 or x.shape != t.shape:
        raise InputError(f"{name}: times and positions must be two (N,) arrays, got {t.shape} and {x.shape}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(x))):
        raise InputError(f"{name}: times and positions must be finite")
    if t.size < 2 or np.any(np.diff(t) <= 0):
        raise InputError(f"{name}: times must be strictly increasing (at least 2 samples)")
    return t, x


def _correlations(t_a: FloatArray, z_a: FloatArray, t_b: FloatArray, x_b: FloatArray, lags: FloatArray) -> FloatArray:
    """``(K,)`` Pearson correlation of standardised ``z_a`` with ``x_b`` interpolated at ``t_a + L``."""
    out = np.empty(lags.size)
    n = z_a.size
    for start in range(0, lags.size, _BLOCK):
        block = lags[start : start + _BLOCK]
        moved = np.interp((t_a[None, :] + block[:, None]).ravel(), t_b, x_b).reshape(block.size, n)
        moved -= moved.mean(axis=1, keepdims=True)
        norm = np.linalg.norm(moved, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            out[start : start + block.size] = np.where(norm > 0, moved @ z_a / (norm * np.sqrt(n)), 0.0)
    return out


def _refine(lags: FloatArray, r: FloatArray, k: int) -> float:
    """Sub-grid peak: vertex of the parabola through ``r[k-1], r[k], r[k+1]`` (kept within one step)."""
    denominator = r[k - 1] - 2 * r[k] + r[k + 1]
    if denominator >= 0:
        return float(lags[k])
    offset = 0.5 * (r[k - 1] - r[k + 1]) / denominator
    return float(lags[k] + np.clip(offset, -1.0, 1.0) * (lags[1] - lags[0]))


def _regression(
    t_a: FloatArray, x_a: FloatArray, t_b: FloatArray, x_b: FloatArray, lag: float, step: float
) -> tuple[float, float, float, float]:
    """``(sd_lag, residual_sd, scale, n_effective)`` of ``x_a = α + β x_b(t_a + lag)`` (module docstring)."""
    moved = np.interp(t_a + lag, t_b, x_b)
    # Slope of the moving signal over a window wider than its sample spacing: the linear
    # interpolant's derivative is piecewise constant, and its local average is the velocity.
    h = max(step, float(np.median(np.diff(t_b))))
    velocity = (np.interp(t_a + lag + h, t_b, x_b) - np.interp(t_a + lag - h, t_b, x_b)) / (2 * h)
    design = np.column_stack([np.ones_like(moved), moved])
    (alpha, beta), *_ = np.linalg.lstsq(design, x_a, rcond=None)
    residual = x_a - alpha - beta * moved
    n = x_a.size
    sigma2 = float(residual @ residual) / (n - 3)
    centred = residual - residual.mean()
    denominator = float(centred @ centred)
    rho = float(centred[1:] @ centred[:-1]) / denominator if denominator > 0 else 0.0
    # Negative autocorrelation would shrink the SD: not trusted. Above 0.95 (inflation 39x) the
    # residual is a smooth model mismatch rather than noise (noise-free signals, interpolation error),
    # and the SD is then a bound on its effect, not a sampling statistic.
    rho = float(np.clip(rho, 0.0, 0.95))
    inflation = (1 + rho) / (1 - rho)
    jacobian = np.column_stack([np.ones(n), moved, beta * velocity])
    information = jacobian.T @ jacobian
    try:
        covariance = np.linalg.inv(information) * sigma2 * inflation
        sd = float(np.sqrt(max(covariance[2, 2], 0.0)))
    except np.linalg.LinAlgError:
        sd = float("inf")
    return sd, float(np.sqrt(sigma2)), float(beta), n / inflation


def estimate_lag(
    t_a: ArrayLike,
    x_a: ArrayLike,
    t_b: ArrayLike,
    x_b: ArrayLike,
    *,
    max_lag_s: float = DEFAULT_MAX_LAG_S,
    resolution_s: float = DEFAULT_RESOLUTION_S,
    allow_inverted: bool = False,
    names: tuple[str, str] = ("fixed signal", "moving signal"),
) -> LagEstimate:
    """Lag of the moving signal ``b`` behind the fixed signal ``a`` by normalised cross-correlation.

    Args:
        t_a: ``(N,)`` fixed signal's times (e.g. video frames), seconds, strictly increasing.
        x_a: ``(N,)`` fixed signal's positions (any unit, e.g. pixels of the line's offset).
        t_b: ``(M,)`` moving signal's times (tracker or joint log), seconds, strictly increasing.
        x_b: ``(M,)`` moving signal's positions (any unit, e.g. metres along the motion axis).
        max_lag_s: the search covers ``[-max_lag_s, max_lag_s]``.
        resolution_s: grid step of the search (the peak is then refined below it).
        allow_inverted: also try ``-x_b`` (the sign of a principal motion axis is arbitrary) and
            keep the polarity of the higher correlation peak.
        names: the two signals' names, for refusals.

    Returns:
        The :class:`LagEstimate` (sign convention in the module docstring).

    Raises:
        InputError: malformed signals or search settings.
        DegenerateDataError: overlap shorter than the search needs, a signal without motion, a
            correlation peak at the edge of the search range, or a lag not determined within it
            (:data:`DETERMINED_SD`).
    """
    ta, xa = _signal(t_a, x_a, names[0])
    tb, xb = _signal(t_b, x_b, names[1])
    if not (np.isfinite(max_lag_s) and max_lag_s > 0):
        raise InputError(f"the maximum lag must be a positive number of seconds, got {max_lag_s}")
    if not (np.isfinite(resolution_s) and 0 < resolution_s <= max_lag_s / 2):
        raise InputError(f"the lag resolution must be in (0, max lag / 2] seconds, got {resolution_s}")
    inside = (ta >= tb[0] + max_lag_s) & (ta <= tb[-1] - max_lag_s)
    if inside.sum() < MIN_SAMPLES:
        raise DegenerateDataError(
            f"only {int(inside.sum())} {names[0]} samples lie within the {names[1]}'s span shortened by the "
            f"±{max_lag_s:g} s search (need {MIN_SAMPLES}): the recordings barely overlap"
        )
    ta, xa = ta[inside], xa[inside]
    for name, x in ((names[0], xa), (names[1], xb[(tb >= ta[0] - max_lag_s) & (tb <= ta[-1] + max_lag_s)])):
        if x.size < 2 or np.ptp(x) <= 1e-12 * max(1.0, float(np.max(np.abs(x)))):
            raise DegenerateDataError(f"the {name} does not move over the overlap: no motion to align")
    z_a = (xa - xa.mean()) / xa.std()
    count = int(np.floor(max_lag_s / resolution_s + 1e-9))
    lags = np.arange(-count, count + 1, dtype=float) * resolution_s
    r = _correlations(ta, z_a, tb, xb, lags)
    candidates = [(int(np.argmax(r)), False)]
    if allow_inverted:
        candidates.append((int(np.argmin(r)), True))
    # Between the two polarities, the better alignment (higher peak; on a tie, the smaller |lag|).
    # PLUS keeps the smaller |lag| outright, which picks the half-period shift of the wrong polarity
    # whenever the true lag exceeds a quarter period of a near-periodic motion.
    k, inverted = max(candidates, key=lambda c: (abs(r[c[0]]), -abs(lags[c[0]])))
    curve: FloatArray = -r if inverted else r
    if k in (0, lags.size - 1):
        raise DegenerateDataError(
            f"the correlation peak lies at the edge of the search range (lag {lags[k]:+.3f} s of ±{max_lag_s:g} s): "
            "the lag is larger than the search, or the signals do not share their motion"
        )
    lag = _refine(lags, curve, k)
    sign = -1.0 if inverted else 1.0
    sd, residual_sd, scale, n_effective = _regression(ta, xa, tb, sign * xb, lag, resolution_s)
    if not DETERMINED_SD * sd <= max_lag_s:
        raise DegenerateDataError(
            f"the lag is not determined: {lag:+.3f} s with SD {sd:.3f} s, wider than the ±{max_lag_s:g} s search "
            "(too little shared motion for the noise)"
        )
    return LagEstimate(
        lag_s=lag,
        sd_s=sd,
        correlation=float(curve[k]),
        inverted=inverted,
        n_samples=int(xa.size),
        n_effective=float(n_effective),
        residual_sd=residual_sd,
        scale=sign * scale,
        lags_s=lags,
        correlations=curve,
    )


def principal_motion(positions: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Positions projected on their principal axis of motion (PLUS's principal motion detection).

    Args:
        positions: ``(N, 3)`` positions (e.g. the probe in the reference frame, metres).

    Returns:
        ``(projection (N,), axis (3,))``: the positions minus their mean, along the unit axis of
        largest variance (sign fixed so the axis's largest component is positive).

    Raises:
        DegenerateDataError: fewer than 2 positions, or all equal.
    """
    P = np.asarray(positions, dtype=float)
    if P.ndim != 2 or P.shape[1] != 3 or P.shape[0] < 2 or not np.all(np.isfinite(P)):
        raise DegenerateDataError(f"principal motion needs (N >= 2, 3) finite positions, got shape {P.shape}")
    centred = P - P.mean(axis=0)
    _, s, vt = np.linalg.svd(centred, full_matrices=False)
    if s[0] <= 0:
        raise DegenerateDataError("the positions do not move: no principal motion")
    axis = vt[0] * np.sign(vt[0][np.argmax(np.abs(vt[0]))])
    return centred @ axis, axis


# --- the two routes: PLUS files (video + tracker), and video + robot joint log --------------------

#: PLUS's smallest peak-to-peak swing of the tracker signal (``MINIMUM_TRACKER_SIGNAL_PEAK_TO_PEAK_MM``),
#: metres: less and PLUS refuses the recording as without motion.
MIN_SWING_M = 8e-3
#: PLUS's smallest peak-to-peak swing of the video signal (``MINIMUM_VIDEO_SIGNAL_PEAK_TO_PEAK_PIXEL``), pixels.
MIN_SWING_PX = 30.0


def tracker_positions(
    path: str | os.PathLike[str], probe: str = "ProbeToTracker", reference: str = "ReferenceToTracker"
) -> tuple[FloatArray, FloatArray]:
    """The probe's positions in the reference frame from a PLUS tracker sequence.

    Args:
        path: the tracker's ``.igs.mha``/``.seq.mha`` (frame fields ``<probe>Transform``,
            ``<reference>Transform`` with their ``*Status`` and ``Timestamp``).
        probe: the probe's tool transform name (PLUS's ``ProbeToTracker``).
        reference: the reference's (PLUS's ``ReferenceToTracker``); PLUS's ProbeToReference is
            ``inv(ReferenceToTracker) @ ProbeToTracker``.

    Returns:
        ``(times (M,) seconds, p_reference_probe (M, 3) metres)`` of the items where both tools
        are tracked (status OK).

    Raises:
        InputError: naming the file and frame of a malformed transform or timestamp, or a file
            where no item has both tools.
    """
    _, frames = read_sequence_header(path)
    times, positions = [], []
    for k, fields in enumerate(frames):
        T_tracker_probe = sequence_transform(fields, probe + "Transform", path, k)
        T_tracker_reference = sequence_transform(fields, reference + "Transform", path, k)
        if T_tracker_probe is None or T_tracker_reference is None:
            continue
        text = fields.get("Timestamp")
        try:
            t = float(text) if text is not None else float("nan")
        except ValueError:
            t = float("nan")
        if not np.isfinite(t):
            raise InputError(
                f"timestamp is not a number: {text!r}", file=path, row=k, row_label="frame", column="Timestamp"
            )
        times.append(t)
        positions.append(np.linalg.solve(T_tracker_reference, T_tracker_probe)[:3, 3])
    if len(times) < 2:
        raise InputError(f"fewer than 2 items track both {probe} and {reference} (status OK)", file=path)
    stamps = np.array(times)
    if np.any(np.diff(stamps) <= 0):
        k = int(np.argmax(np.diff(stamps) <= 0)) + 1
        raise InputError(f"timestamps are not strictly increasing at item {k}", file=path)
    return stamps, np.array(positions)


@dataclass(frozen=True)
class TemporalResult:
    """A temporal calibration: the lag and the two signals it aligned.

    Attributes:
        estimate: the :class:`LagEstimate` (lag of the pose stream behind the video).
        video_times_s: ``(N,)`` every video frame's timestamp, seconds.
        line: the tank line in every frame (:class:`~brachycal.imaging.tank_line.TankLineTrack`).
        pose_times_s: ``(M,)`` the pose stream's times used, seconds.
        pose_position_m: ``(M,)`` the probe's position along its principal motion axis, metres.
        axis: ``(3,)`` the principal motion axis (unit, in the poses' frame).
        swing_m: peak-to-peak of ``pose_position_m`` over the video's span.
        swing_px: peak-to-peak of the line's position.
    """

    estimate: LagEstimate
    video_times_s: FloatArray
    line: TankLineTrack
    pose_times_s: FloatArray
    pose_position_m: FloatArray
    axis: FloatArray
    swing_m: float
    swing_px: float


def lag_from_signals(
    video_times_s: ArrayLike,
    line: TankLineTrack,
    pose_times_s: ArrayLike,
    positions_m: ArrayLike,
    *,
    max_lag_s: float = DEFAULT_MAX_LAG_S,
    resolution_s: float = DEFAULT_RESOLUTION_S,
    names: tuple[str, str] = ("video", "pose stream"),
    sources: tuple[str | os.PathLike[str] | None, str | os.PathLike[str] | None] = (None, None),
) -> TemporalResult:
    """Lag of a pose stream behind a video of the tank bottom (both routes end here).

    The poses within the video's span (widened by twice the search) are projected on their principal
    motion axis (:func:`principal_motion`); the video's frames with a detected line give the line's
    offset (:class:`~brachycal.imaging.tank_line.TankLineTrack`). Both must swing at least PLUS's
    minimum (:data:`MIN_SWING_M`, :data:`MIN_SWING_PX`). The line and the probe may move in the
    same or opposite senses (``allow_inverted``).

    Args:
        video_times_s: ``(N,)`` frame timestamps on the video's clock, seconds.
        line: the tank line of the same N frames.
        pose_times_s: ``(M,)`` pose times on the pose stream's clock, seconds.
        positions_m: ``(M, 3)`` probe (or image) positions in a fixed frame, metres.
        names: the two streams' names, for refusals.
        sources: the two streams' files, named by the refusals about each.

    Raises:
        DegenerateDataError: too few frames with a line, too little motion, or no lag found
            (:func:`estimate_lag`).
    """
    t_video = np.asarray(video_times_s, dtype=float)
    t_pose = np.asarray(pose_times_s, dtype=float)
    P = np.asarray(positions_m, dtype=float)
    ok = line.detected & np.isfinite(t_video)
    if ok.sum() < MIN_SAMPLES:
        first = next((f"; frame {k}: {r}" for k, r in enumerate(line.reasons) if r), "")
        raise DegenerateDataError(
            f"the tank bottom was found in {int(ok.sum())} of {t_video.size} frames (need {MIN_SAMPLES}){first}",
            file=sources[0],
        )
    t_a, x_a = t_video[ok], line.offset_px[ok]
    # Poses over the video's span widened by twice the search: every frame then keeps its
    # shifted time inside them for every lag searched (estimate_lag drops frames that do not).
    near = (t_pose >= t_a[0] - 2 * max_lag_s) & (t_pose <= t_a[-1] + 2 * max_lag_s)
    if near.sum() < 2:
        raise DegenerateDataError(
            f"the {names[1]} holds no sample within the {names[0]}'s span ± {2 * max_lag_s:g} s", file=sources[1]
        )
    x_b, axis = principal_motion(P[near])
    swing_m, swing_px = float(np.ptp(x_b)), float(np.ptp(x_a))
    if swing_m < MIN_SWING_M:
        raise DegenerateDataError(
            f"the probe moves {swing_m * 1e3:.1f} mm along its main axis during the {names[0]} "
            f"(PLUS needs {MIN_SWING_M * 1e3:g} mm)",
            file=sources[1],
        )
    if swing_px < MIN_SWING_PX:
        raise DegenerateDataError(
            f"the tank bottom moves {swing_px:.1f} px in the {names[0]} (PLUS needs {MIN_SWING_PX:g} px)",
            file=sources[0],
        )
    estimate = estimate_lag(
        t_a, x_a, t_pose[near], x_b, max_lag_s=max_lag_s, resolution_s=resolution_s, allow_inverted=True, names=names
    )
    return TemporalResult(estimate, t_video, line, t_pose[near], x_b, axis, swing_m, swing_px)


def lag_from_plus_files(
    video: str | os.PathLike[str],
    tracker: str | os.PathLike[str],
    *,
    config: str | os.PathLike[str] | None = None,
    probe: str = "ProbeToTracker",
    reference: str = "ReferenceToTracker",
    max_lag_s: float | None = None,
    resolution_s: float = DEFAULT_RESOLUTION_S,
    clip: tuple[int, int, int, int] | None = None,
) -> TemporalResult:
    """PLUS's temporal calibration from its two recordings: the tracker's lag behind the video.

    Args:
        video: the B-mode sequence of the tank bottom (``.igs.mha``).
        tracker: the tracker sequence (``ProbeToTracker``/``ReferenceToTracker`` per item).
        config: a PLUS device set; its temporal-calibration clip rectangle and search range are
            used unless ``clip``/``max_lag_s`` are given.
        clip: ``(u, v, width, height)`` of the line search, pixels (default: the device set's, or
            the whole image).
        max_lag_s: search range (default: the device set's, or :data:`DEFAULT_MAX_LAG_S`).

    Returns:
        The :class:`TemporalResult`; ``estimate.lag_s`` is PLUS's ``TrackerLagSec``.
    """
    settings = read_plus_temporal_settings(config) if config is not None else PlusTemporalSettings()
    if clip is not None:
        origin: tuple[int, int] | None = (clip[0], clip[1])
        size: tuple[int, int] | None = (clip[2], clip[3])
    else:
        origin, size = settings.clip_origin, settings.clip_size
    lag_range = max_lag_s if max_lag_s is not None else (settings.max_lag_s or DEFAULT_MAX_LAG_S)
    sequence = read_image_sequence(video)
    if np.isnan(sequence.timestamps_s).any():
        k = int(np.argmax(np.isnan(sequence.timestamps_s)))
        raise InputError("frame has no Timestamp", file=video, row=k, row_label="frame", column="Timestamp")
    try:
        line = find_tank_line(sequence.pixels, clip_origin=origin, clip_size=size)
    except InputError as exc:
        raise InputError(str(exc), file=video) from None
    t_pose, P = tracker_positions(tracker, probe, reference)
    return lag_from_signals(
        sequence.timestamps_s,
        line,
        t_pose,
        P,
        max_lag_s=lag_range,
        resolution_s=resolution_s,
        names=("video", "tracker"),
        sources=(video, tracker),
    )


#: Former names, given for one release with a DeprecationWarning.
if not TYPE_CHECKING:  # type checkers see only the new names
    __getattr__ = renamed(__name__, {"TemporalCalibration": "TemporalResult"})
