"""Image-to-probe calibration, §II.D: eq. (8) points, eq. (9) by several methods, LOO-CV (§III.A).

Every method yields an :class:`ImageCalibration`: a rigid ``T_Ptip_I`` and the pixel spacing
(metres per pixel) it goes with; fits the samples cannot determine are refused.

Design: ``docs/design/sequential.md``, "Image-to-probe calibration".
"""

from __future__ import annotations

import warnings

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from brachycal.calibration.labels import ALL_LABELS as ALL_LABELS
from brachycal.calibration.labels import METHOD_LABELS as METHOD_LABELS
from brachycal.calibration.labels import METHODS as METHODS
from brachycal.calibration.labels import PAPER_METHODS as PAPER_METHODS
from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.result import ImageCalibration, PredictedUncertainty
from brachycal.calibration.sequential import registration
from brachycal.errors import ConditioningWarning, DegenerateDataError, InputError
from brachycal.imaging.pixels import image_points
from brachycal.se3 import FloatArray, inverse, transform_points

# ALL_LABELS, METHOD_LABELS, METHODS, PAPER_METHODS: their home is the light calibration.labels (the
# command line offers them before loading SciPy); imported ``as`` themselves, they stay names of this module.

#: Scale model of each method (:data:`~brachycal.calibration.sequential.registration.SCALE_MODELS`).
SCALE_MODEL = {"icp": "rigid", "kabsch": "rigid", "horn": "rigid", "similarity": "similarity", "scaled_uv": "uv"}

#: Annotation noise of the needle tip in an image, pixels per axis (1 SD): the paper's operators
#: pick the brightest pixel of the tip's echo, about a pixel wide.
ANNOTATION_SD_PX = 1.0
#: Distance from the samples' centroid at which the fit's predicted error is judged, metres: the
#: needle is targeted within about this of the image's centre (the prostate is ~50 mm across).
REACH_M = 0.05
#: Predicted 3D SD at the reach above which a fit is refused, metres.
MAX_REACH_SD_M = 2e-3
#: Predicted 3D SD at the reach above which a fit warns, metres.
WARN_REACH_SD_M = 5e-4
#: Fitted spacing over nominal beyond this factor (either way) is refused.
MAX_SPACING_FACTOR = 1.5
#: Fitted spacing off the nominal by more than this fraction warns.
WARN_SPACING_CHANGE = 0.10
#: ICP's image frame this far from the URDF's nominal (rotation, degrees; origin shift, metres)
#: warns that the nominal is off: beyond any mounting tolerance of a probe holder (a few mm and
#: degrees; the digital twin draws 2 mm / 1° SD).
NOMINAL_ANGLE_DEG = 10.0
NOMINAL_SHIFT_M = 0.010


def probe_points(T_R_ER: ArrayLike, T_R_EL: ArrayLike, p_ER_Ntip: ArrayLike, T_EL_Ptip: ArrayLike) -> FloatArray:
    """Eq. (8): needle tips in the probe frame, ``(N, 3)``, from flange poses ``(N, 4, 4)``."""
    p_R_Ntip = transform_points(np.asarray(T_R_ER), np.asarray(p_ER_Ntip))
    return transform_points(inverse(np.asarray(T_R_EL) @ np.asarray(T_EL_Ptip)), p_R_Ntip)


def _second_spread(points: FloatArray) -> float:
    """Second principal SD of ``(N, 3)`` points (their spread across their long axis), metres."""
    centred = points - points.mean(axis=0)
    return float(np.linalg.svd(centred, compute_uv=False)[1] / np.sqrt(len(points)))


def _check_spread(p_I: FloatArray, p_Ptip: FloatArray, sigma_m: float, spacing: FloatArray, noise_px: float) -> None:
    """Refuse sample sets whose spread cannot fix the image plane's tilt (module docstring)."""
    n = len(p_I)
    least = REACH_M * sigma_m / (np.sqrt(n) * MAX_REACH_SD_M)
    pixel = float(np.mean(spacing))
    spread = _second_spread(p_I)
    if spread < least:
        raise DegenerateDataError(
            f"the annotated needle tips spread only {spread / pixel:.2f} px (SD) across their narrowest direction: "
            f"with {n} samples and {noise_px:g} px annotation noise the image plane's tilt needs at least "
            f"{least / pixel:.2f} px; spread the needle positions over the image"
        )
    spread = _second_spread(p_Ptip)
    if spread < least:
        raise DegenerateDataError(
            f"the needle tips in the probe frame (eq. 8) spread only {spread * 1e3:.3f} mm (SD) across their "
            f"narrowest direction, {n} samples: at least {least * 1e3:.3f} mm is needed; were all images taken at "
            "one robot pose? move the needle (or the probe) between images"
        )


def _check_spacing(method: str, fitted: FloatArray, nominal: FloatArray, factor_sd: FloatArray, warn: bool) -> None:
    """Refuse spacings that are not positive, or implausible beyond their own uncertainty; warn off by > 10 %.

    ``factor_sd (2,)``: predicted SD of ``fitted / nominal`` from the fit's residual. Noisy data may
    put the fitted factor beyond :data:`MAX_SPACING_FACTOR` by chance; refused only when it lies
    further than 3 predicted SDs outside the plausible range.
    """
    ratio = fitted / nominal
    text = f"{method}: fitted pixel spacing {fitted[0] * 1e3:.4g} x {fitted[1] * 1e3:.4g} mm/px against the nominal "
    text += f"{nominal[0] * 1e3:.4g} x {nominal[1] * 1e3:.4g}"
    outside = np.maximum.reduce([1 / MAX_SPACING_FACTOR - ratio, ratio - MAX_SPACING_FACTOR, np.zeros(2)])
    if np.any(ratio <= 0) or np.any(outside > 3 * factor_sd):
        raise DegenerateDataError(
            f"{text}, off by more than a factor {MAX_SPACING_FACTOR:g} (beyond 3 predicted SDs): implausible (sound "
            "speed changes it by -9..+7 %); check the spacing in session.toml and that the samples show the needle "
            "where annotated"
        )
    if warn and np.any(np.abs(ratio - 1) > WARN_SPACING_CHANGE):
        warnings.warn(
            f"{text}, off by {np.abs(ratio - 1).max() * 100:.1f} % (> {WARN_SPACING_CHANGE * 100:.0f} %, more than "
            f"the speed of sound explains; predicted SD {factor_sd.max() * 100:.1f} %); check the spacing in "
            "session.toml",
            ConditioningWarning,
            stacklevel=4,
        )


def _check_nominal(result: registration.IcpResult, T_nominal: FloatArray, p_I: FloatArray, warn: bool) -> None:
    R_rel = result.T[:3, :3] @ T_nominal[:3, :3].T
    angle = float(np.degrees(np.linalg.norm(Rotation.from_matrix(R_rel).as_rotvec())))
    shift = float(np.linalg.norm(result.T[:3, 3] - T_nominal[:3, 3]))
    if angle <= NOMINAL_ANGLE_DEG and shift <= NOMINAL_SHIFT_M:
        return
    where = f"{angle:.1f} deg and {shift * 1e3:.1f} mm from the URDF's nominal us_image"
    if result.ties:
        apart = max(registration.displacement(result.T, T, p_I) for T, _ in result.ties)
        raise DegenerateDataError(
            f"icp: {len(result.ties) + 1} fits match the samples equally well (RMS {result.rms_m * 1e3:.3g} mm; "
            f"{apart * 1e3:.0f} mm apart over the samples) and the nearest is {where} (> {NOMINAL_ANGLE_DEG:g} deg "
            f"or {NOMINAL_SHIFT_M * 1e3:g} mm), so the nominal cannot choose: the pattern of needle positions is "
            "symmetric; annotate an asymmetric one, correct the URDF's nominal image frame, or leave icp out "
            "(--methods)"
        )
    if warn:
        warnings.warn(
            f"icp: the fitted image frame is {where} (> {NOMINAL_ANGLE_DEG:g} deg or {NOMINAL_SHIFT_M * 1e3:g} mm): "
            "the URDF's nominal image frame is off (or the probe is mounted otherwise); correct the URDF",
            ConditioningWarning,
            stacklevel=3,
        )


def _check_pairing(result: registration.IcpResult, p_I: FloatArray, p_Ptip: FloatArray, sigma_m: float) -> None:
    """Refuse an ICP fit that contradicts the recorded pairs of pixels and probe-frame points.

    ICP does not use the pairs, but they exist: its fit must put each sample near its own probe
    point, not merely near some sample's. Its RMS against the recorded pairs, ``r_pairs``, may
    exceed its nearest-neighbour RMS ``r_nn`` only as much as the tie tolerance of
    :func:`~brachycal.calibration.sequential.registration.icp_global` allows,
    ``r_pairs² ≤ r_nn² + max(√3 σ_a, r_nn)²``; a mirror-image twin of the true fit (a symmetric
    pattern of samples, and a nominal frame that chose the twin) pairs samples across the pattern.
    """
    r_pairs = float(np.sqrt(np.mean(np.sum((transform_points(result.T, p_I) - p_Ptip) ** 2, axis=1))))
    tolerance = max(np.sqrt(3.0) * sigma_m, result.rms_m)
    if r_pairs**2 > result.rms_m**2 + tolerance**2:
        raise DegenerateDataError(
            f"icp: its fit puts the samples on other samples' probe-frame points (RMS {r_pairs * 1e3:.3g} mm against "
            f"the recorded pairs, {result.rms_m * 1e3:.3g} mm to the nearest points): the pattern of needle positions "
            "is symmetric and the URDF's nominal image frame chose the mirror image of the fit; correct the nominal, "
            "annotate an asymmetric pattern, or leave icp out (--methods)"
        )


def _uncertainty(
    method: str,
    p_I: FloatArray,
    paired: FloatArray,
    T: FloatArray,
    spacing: FloatArray,
    fitted: FloatArray,
    sigma_floor_m: float,
    warn: bool,
) -> PredictedUncertainty:
    """Predicted uncertainty of a fit, and the reach check (module docstring)."""
    model = SCALE_MODEL[method]
    factors = np.append(fitted / spacing, 1.0)
    fit_unc = registration.fit_uncertainty(p_I, paired, T, model=model, scale=factors)
    if model != "rigid":
        _check_spacing(method, fitted, spacing, np.broadcast_to(fit_unc.scale_sd(), (2,)), warn)
    centre = p_I.mean(axis=0)
    directions = np.linalg.svd(p_I - centre, full_matrices=False)[2][:2]
    reach_points = centre + REACH_M * np.concatenate([directions, -directions])
    # The SD at a point is proportional to the noise level: one propagation at unit noise serves both.
    reach_unit = float(fit_unc.point_sd_m(reach_points, 1.0).max())
    # Refusal from the design alone (at the stated annotation noise): data that are merely noisy
    # still determine the fit, and are reported with the warning and the predicted figures.
    reach_design = sigma_floor_m * reach_unit
    if reach_design > MAX_REACH_SD_M:
        raise DegenerateDataError(
            f"{method}: the samples do not determine the image calibration: predicted error "
            f"{reach_design * 1e3:.3g} mm at {REACH_M * 1e3:.0f} mm from the samples' centre "
            f"(> {MAX_REACH_SD_M * 1e3:g} mm) even at {sigma_floor_m * 1e3:.3g} mm annotation noise; spread the "
            "needle positions over the image and the probe poses"
        )
    reach_fit = fit_unc.noise_sd_m * reach_unit
    reach_check = max(reach_design, reach_fit)
    if warn and reach_check > WARN_REACH_SD_M:
        warnings.warn(
            f"{method}: the image calibration is poorly determined: predicted error {reach_check * 1e3:.3g} mm at "
            f"{REACH_M * 1e3:.0f} mm from the samples' centre (> {WARN_REACH_SD_M * 1e3:g} mm; "
            f"{fit_unc.noise_sd_m * 1e3:.3g} mm residual noise per coordinate)",
            ConditioningWarning,
            stacklevel=3,
        )
    scale_sd = fit_unc.scale_sd()
    if model == "similarity":
        spacing_sd = scale_sd[0] * spacing
    elif model == "uv":
        spacing_sd = scale_sd * spacing
    else:
        spacing_sd = np.zeros(2)
    return PredictedUncertainty(
        noise_sd_m=fit_unc.noise_sd_m,
        rotation_sd_deg=float(np.degrees(fit_unc.rotation_sd_rad())),
        origin_sd_m=fit_unc.translation_sd_m(),
        spacing_sd_m=spacing_sd,
        # Σ_i tr(J_i (JᵀJ)⁻¹ J_iᵀ) = tr(I_p) = p (the hat matrix's trace): the samples' mean variance
        # is σ̂² p / N for every design, no propagation needed.
        samples_sd_m=fit_unc.noise_sd_m * float(np.sqrt(fit_unc.cov_unit.shape[0] / len(p_I))),
        reach_sd_m=reach_fit,
    )


def fit(
    method: str,
    uv_px: ArrayLike,
    p_Ptip: ArrayLike,
    spacing_m: ArrayLike,
    T_Ptip_I_init: ArrayLike | None = None,
    *,
    warn: bool = True,
    icp_starts: list[FloatArray] | None = None,
    noise_px: float = ANNOTATION_SD_PX,
) -> ImageCalibration:
    """Solve eq. (9) with one method, check its conditioning, predict its uncertainty.

    Args:
        method: one of :data:`METHODS`.
        uv_px: ``(N, 2)`` annotated pixels.
        p_Ptip: ``(N, 3)`` the same needle tips in the probe frame (eq. 8), metres.
        spacing_m: ``(2,)`` nominal pixel spacing, metres.
        T_Ptip_I_init: ``(4, 4)`` ICP's prior guess (e.g. the URDF's nominal frame): one of its starts,
            the tie-breaker, and what its result is compared with.
        warn: emit :class:`ConditioningWarning` for grey-zone fits (leave-one-out folds pass False;
            refusals stay).
        icp_starts: ICP's other starts (default: 48 orientations from the principal axes).
        noise_px: annotation noise, pixels per axis (module docstring).

    Raises:
        DegenerateDataError: the samples cannot determine the fit (module docstring).
    """
    spacing = np.asarray(spacing_m, dtype=float)
    uv = np.asarray(uv_px, dtype=float)
    p_I = image_points(uv, spacing)
    p = np.asarray(p_Ptip, dtype=float)
    if p.shape != p_I.shape:
        raise InputError(f"image and probe-frame points differ in shape: {p_I.shape} vs {p.shape}")
    if len(p_I) < 3 or not np.all(np.isfinite(p_I)) or not np.all(np.isfinite(p)):
        registration.check_geometry(p_I, "image points")  # says what is wrong
        raise InputError("probe-frame points contain NaN or infinite values")
    sigma_floor = noise_px * float(spacing.max())
    _check_spread(p_I, p, sigma_floor, spacing, noise_px)  # collinear points too, with their figure
    paired, fitted = p, spacing
    if method == "kabsch":
        T = registration.kabsch(p_I, p)
    elif method == "horn":
        T = registration.horn(p_I, p)
    elif method == "icp":
        if T_Ptip_I_init is None:
            raise InputError("ICP needs a prior guess of T_Ptip_I (e.g. the URDF's nominal us_image)")
        nominal = np.asarray(T_Ptip_I_init, dtype=float)
        result = registration.icp_global(p_I, p, nominal, starts=icp_starts, tie_m=np.sqrt(3.0) * sigma_floor)
        _check_nominal(result, nominal, p_I, warn)
        _check_pairing(result, p_I, p, sigma_floor)
        T, paired = result.T, p[result.match]
    elif method == "similarity":
        T, scale = registration.similarity(p_I, p)
        fitted = spacing * scale
    elif method == "scaled_uv":
        T, fitted = registration.scaled_uv(uv, p, spacing)
    else:
        raise InputError(f"unknown registration method {method!r}; choose from {', '.join(METHODS)}")
    uncertainty = _uncertainty(method, p_I, paired, T, spacing, fitted, sigma_floor, warn)
    return ImageCalibration(method, T, fitted, uncertainty)


def predict_base(
    calibration: ImageCalibration, T_R_EL: ArrayLike, T_EL_Ptip: ArrayLike, uv_px: ArrayLike
) -> FloatArray:
    """``P (N, 3)`` in ``base_link``: ``T_R_EL @ T_EL_Ptip @ T_Ptip_I @ p_I`` for pixels ``(N, 2)``."""
    T_R_I = np.asarray(T_R_EL) @ np.asarray(T_EL_Ptip) @ calibration.T_Ptip_I
    return transform_points(T_R_I, calibration.image_points(uv_px))


def leave_one_out_points(
    method: str,
    uv_px: ArrayLike,
    T_R_ER: ArrayLike,
    T_R_EL: ArrayLike,
    p_ER_Ntip: ArrayLike,
    T_EL_Ptip: ArrayLike,
    spacing_m: ArrayLike,
    T_Ptip_I_init: ArrayLike | None = None,
    *,
    full: ImageCalibration | None = None,
) -> tuple[FloatArray, FloatArray]:
    """``(P_real (N, 3), P_cal (N, 3))`` in ``base_link``: each P_cal(i) from a fit without sample i.

    ``full``: for ICP, its fit on all the samples from the same prior (what :func:`fit` returned),
    if already computed: it starts every fold, instead of a global ICP run (49 starts) again.
    """
    uv = np.asarray(uv_px, dtype=float)
    T_R_ER, T_R_EL = np.asarray(T_R_ER), np.asarray(T_R_EL)
    if len(uv) < 4:
        raise InputError(f"{len(uv)} samples: leave-one-out needs at least 4 (each fit needs 3)")
    p_Ptip = probe_points(T_R_ER, T_R_EL, p_ER_Ntip, T_EL_Ptip)
    p_real = transform_points(T_R_ER, np.asarray(p_ER_Ntip))
    p_cal = np.empty_like(p_real)
    starts: list[FloatArray] | None = None
    if method == "icp" and T_Ptip_I_init is not None:
        # Each fold starts from the all-sample fit (found from many starts): a fold differs by one
        # sample, so its fit lies next to it; restarting every fold from 48 orientations would
        # only find the all-sample fit's ties again, and the all-sample fit breaks those ties.
        if full is None:
            spacing = np.asarray(spacing_m, dtype=float)
            sigma = ANNOTATION_SD_PX * float(spacing.max())
            T_full = registration.icp_global(
                image_points(uv, spacing), p_Ptip, T_Ptip_I_init, tie_m=np.sqrt(3.0) * sigma
            ).T
        elif full.method != "icp":
            raise InputError(f"leave-one-out of icp started from a {full.method} fit: pass the icp fit")
        else:
            T_full = full.T_Ptip_I
        T_Ptip_I_init, starts = T_full, []
    keep = np.ones(len(uv), dtype=bool)
    for i in range(len(uv)):
        keep[i] = False
        try:
            calibration = fit(method, uv[keep], p_Ptip[keep], spacing_m, T_Ptip_I_init, warn=False, icp_starts=starts)
        except DegenerateDataError as exc:
            raise DegenerateDataError(f"leave-one-out fold without sample #{i + 1}: {exc.problem}") from None
        p_cal[i] = predict_base(calibration, T_R_EL[i], T_EL_Ptip, uv[i])[0]
        keep[i] = True
    return p_real, p_cal


def leave_one_out(
    method: str,
    uv_px: ArrayLike,
    T_R_ER: ArrayLike,
    T_R_EL: ArrayLike,
    p_ER_Ntip: ArrayLike,
    T_EL_Ptip: ArrayLike,
    spacing_m: ArrayLike,
    T_Ptip_I_init: ArrayLike | None = None,
    *,
    full: ImageCalibration | None = None,
) -> ErrorStats:
    """Table II figures of one method: N fits on N−1 samples, each predicting the one left out
    (``full``: as in :func:`leave_one_out_points`)."""
    p_real, p_cal = leave_one_out_points(
        method, uv_px, T_R_ER, T_R_EL, p_ER_Ntip, T_EL_Ptip, spacing_m, T_Ptip_I_init, full=full
    )
    return ErrorStats.between(p_real, p_cal)
