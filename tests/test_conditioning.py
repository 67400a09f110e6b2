"""Conditioning of every estimator: exact data pass and recover the truth, degenerate data are refused
with the figure that failed, grey-zone data warn, and each predicted uncertainty matches the spread
of its estimate over repeated noisy draws.

"Matches" means: over 200 draws, the RMS of the estimate's error lies within a factor 0.8–1.25 of
the RMS of the predicted SDs (measured: 0.92–1.06). The predictions are linear error propagation
with the noise the estimator assumes; the factor leaves room for the sampling error of 200 draws
(about 5 %) and the linearisation, and fails a prediction off by a factor √2 (a forgotten term,
a covariance instead of its square root, a wrong degree-of-freedom count with few data).
"""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest
from bands import assert_calibrated, assert_unbiased_variance
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation
from scipy.stats import binom, chi2

from brachycal.calibration import calibrate, pivot_algebraic, pivot_robust
from brachycal.calibration.sequential import image_to_probe, registration
from brachycal.calibration.sequential.tool_rotation import tool_rotation
from brachycal.calibration.sequential.tool_tips import (
    MIN_SEPARATION_SIGMAS,
    TOUCH_SD_M,
    TipEstimate,
    check_distinct_touches,
    check_separation,
    check_tip,
    reference_tip_estimate,
    tool_tip_estimate,
)
from brachycal.data.session import Touches
from brachycal.errors import ConditioningWarning, DegenerateDataError
from brachycal.se3 import make_transform, transform_points
from brachycal.simulation import default_truth, exact_session

DRAWS = 200
#: Accepted ratio of empirical RMS error to predicted RMS SD (module docstring).
LOW, HIGH = 0.8, 1.25
#: Noise-free data recover the truth to this (metres, or unitless rotation entries): round-off
#: of the fits is ~1e-13, far below anything the calibration resolves.
EXACT = 1e-9


def ratio(errors: np.ndarray, predicted_sd: np.ndarray) -> float:
    """Empirical RMS error over predicted RMS SD."""
    return float(np.sqrt(np.mean(np.square(errors))) / np.sqrt(np.mean(np.square(predicted_sd))))


def angle_between(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Rotation angle of ``R_a R_bᵀ``, radians."""
    return float(np.linalg.norm(Rotation.from_matrix(R_a @ R_b.T).as_rotvec()))


@pytest.fixture(scope="module")
def exact_result(robot, exact):
    with warnings.catch_warnings():  # the exact session must not raise a single conditioning warning
        warnings.simplefilter("error", ConditioningWarning)
        return calibrate(exact, robot)


def subset(session, keep: np.ndarray):
    """The session with only the samples ``keep`` (bool mask)."""
    return replace(
        session,
        sample_ids=[s for s, k in zip(session.sample_ids, keep, strict=True) if k],
        samples_q=session.samples_q[keep],
        uv_px=session.uv_px[keep],
    )


def asymmetric(session):
    """Drop every sample at three of the grid's corner pixels: the pattern no longer maps onto itself
    when turned over or mirrored, so correspondence-free ICP has one best fit."""
    us, vs = np.unique(session.uv_px[:, 0]), np.unique(session.uv_px[:, 1])
    corner = [(us[0], vs[0]), (us[0], vs[1]), (us[1], vs[0])]
    keep = np.array([not any(np.allclose(uv, c) for c in corner) for uv in session.uv_px])
    return subset(session, keep)


# --- the whole sequential calibration on exact data --------------------------------------------------


def test_exact_session_passes_every_check_and_predicts_no_uncertainty(exact_result, truth):
    # Built without any ConditioningWarning (fixture). The data are exact, so every predicted SD from
    # the data's own spread or residual is round-off.
    assert np.abs(exact_result.T_ER_Ntip - truth.T_ER_Ntip).max() < EXACT
    for tip in (exact_result.needle.tip, exact_result.probe.tip, *exact_result.reference_tips.values()):
        assert tip.sd_m < EXACT
    for method, calibration in exact_result.image.items():
        assert np.abs(calibration.T_Ptip_I - truth.T_Ptip_I).max() < EXACT, method
        assert calibration.uncertainty.reach_sd_m < EXACT and calibration.uncertainty.noise_sd_m < EXACT
    # The rotations' SDs come from the stated positioning noise (the three-point method has no
    # redundancy to measure it): 2σ/L per axis for 20-mm moves.
    rotation = exact_result.needle.rotation
    assert np.allclose(rotation.direction_sd_deg, np.degrees(2 * TOUCH_SD_M / 0.02), rtol=1e-6)


# --- tool tips --------------------------------------------------------------------------------------


def touch_poses(rng, p_R: np.ndarray, p_E: np.ndarray, trials: int, sigma: float) -> np.ndarray:
    """``(trials, 4, 4)`` flange poses putting the tool tip ``p_E`` on ``p_R`` from varied directions,
    each off by isotropic noise ``sigma`` per axis."""
    R = Rotation.from_euler("y", 135, degrees=True) * Rotation.from_rotvec(rng.normal(scale=0.5, size=(trials, 3)))
    R = R.as_matrix()
    t = p_R + rng.normal(scale=sigma, size=(trials, 3)) - np.einsum("nij,j->ni", R, p_E)
    return make_transform(R, t)


def test_tip_uncertainty_predicts_the_spread_of_the_estimates():
    p_ref, p_Mtip, p_Ntip = np.array([0.75, -0.05, 0.85]), np.array([0.0, 0.0, 0.15]), np.array([0.03, 0.0, 0.28])
    rng = np.random.default_rng(11)
    ref_errors, ref_sd, tip_errors, tip_sd = [], [], [], []
    for _ in range(DRAWS):
        reference = reference_tip_estimate(touch_poses(rng, p_ref, p_Mtip, 3, TOUCH_SD_M), p_Mtip)
        tip = tool_tip_estimate(touch_poses(rng, p_ref, p_Ntip, 3, TOUCH_SD_M), reference)
        ref_errors.append(np.linalg.norm(reference.p - p_ref))
        ref_sd.append(reference.sd_m)
        tip_errors.append(np.linalg.norm(tip.p - p_Ntip))
        tip_sd.append(tip.sd_m)
    assert LOW < ratio(np.array(ref_errors), np.array(ref_sd)) < HIGH
    assert LOW < ratio(np.array(tip_errors), np.array(tip_sd)) < HIGH


def test_tip_noise_estimate_is_unbiased_with_its_degrees_of_freedom():
    # Each trial's point is the tip plus isotropic noise σ per axis (the reference tip: the top-model's
    # tip moved by the noise; the tool tip: the noise turned into the flange frame, the reference exact).
    # Then Σ_t ‖x_t − x̄‖²/σ² ~ χ² with 3(T − 1) degrees of freedom: σ̂² is unbiased over many draws.
    p_ref, p_Mtip, p_Ntip = np.array([0.75, -0.05, 0.85]), np.array([0.0, 0.0, 0.15]), np.array([0.03, 0.0, 0.28])
    exact_reference = TipEstimate(p_ref, p_ref[None], 0.0, np.zeros((3, 3)))
    rng = np.random.default_rng(21)
    for trials in (2, 3, 5):
        reference_ratio, tool_ratio = [], []
        for _ in range(DRAWS):
            reference = reference_tip_estimate(touch_poses(rng, p_ref, p_Mtip, trials, TOUCH_SD_M), p_Mtip)
            tool = tool_tip_estimate(touch_poses(rng, p_ref, p_Ntip, trials, TOUCH_SD_M), exact_reference)
            reference_ratio.append((reference.sigma_m / TOUCH_SD_M) ** 2)
            tool_ratio.append((tool.sigma_m / TOUCH_SD_M) ** 2)
        assert_unbiased_variance(reference_ratio, 3 * (trials - 1))
        assert_unbiased_variance(tool_ratio, 3 * (trials - 1))


def test_tool_tip_intervals_cover_the_truth_at_their_level():
    # The tool tip's error is its own trials' noise plus the reference tip's error seen through the
    # trials' mean orientation: the stated covariance must hold both (95 % ellipsoids cover the truth
    # 95 % of the time). Many trials, so that σ̂ is nearly σ (F distribution with 3(T − 1) dof).
    p_ref, p_Mtip, p_Ntip = np.array([0.75, -0.05, 0.85]), np.array([0.0, 0.0, 0.15]), np.array([0.03, 0.0, 0.28])
    rng = np.random.default_rng(12)
    trials, d2 = 20, []
    for _ in range(DRAWS):
        reference = reference_tip_estimate(touch_poses(rng, p_ref, p_Mtip, trials, TOUCH_SD_M), p_Mtip)
        tip = tool_tip_estimate(touch_poses(rng, p_ref, p_Ntip, trials, TOUCH_SD_M), reference)
        error = tip.p - p_Ntip
        d2.append(error @ np.linalg.solve(tip.cov, error))
    assert_calibrated(d2, 3, dof=3 * (trials - 1))


def test_widely_spread_trials_warn():
    rng = np.random.default_rng(2)
    p_ref, p_Mtip = np.array([0.75, -0.05, 0.85]), np.array([0.0, 0.0, 0.15])
    reference = reference_tip_estimate(touch_poses(rng, p_ref, p_Mtip, 3, 1e-3), p_Mtip)  # 1 mm per axis
    with pytest.warns(ConditioningWarning, match=r"trials spread .* predicted SD .* \(> 0\.5 mm\)"):
        check_tip(reference, "reference tip rtip1")


def test_needle_touching_at_the_top_models_configuration_is_refused(robot, exact):
    touches = dict(exact.touches)
    touches["needle", "rtip1"] = touches["top_model", "rtip1"]
    with pytest.raises(
        DegenerateDataError,
        match=r"needle trial 1 at rtip1 has the joints of the top_model trial 1 .*"
        r"largest difference 0 rad",
    ):
        check_distinct_touches(touches)
    with pytest.raises(DegenerateDataError) as caught:
        calibrate(replace(exact, touches=touches), robot)
    assert caught.value.file == "touches.csv"


def test_all_touches_at_one_configuration_are_refused(robot, exact):
    one = exact.touches["top_model", "rtip1"].q[:1]
    touches = {
        key: Touches(group.trials, np.repeat(one, len(group.trials), axis=0)) for key, group in exact.touches.items()
    }
    with pytest.raises(DegenerateDataError, match="largest difference 0 rad"):
        calibrate(replace(exact, touches=touches), robot)


def test_validation_tip_that_is_the_calibration_tip_is_refused(robot, exact):
    # rtip2 re-touched at rtip1's configurations, each joint 1e-5 rad off (new readings of one point).
    touches = dict(exact.touches)
    for tool in ("top_model", "needle", "probe"):
        group = exact.touches[tool, "rtip1"]
        touches[tool, "rtip2"] = Touches(group.trials, group.q + 1e-5)
    with pytest.raises(
        DegenerateDataError, match=r"rtip1 and rtip2 .* are 0\.0\d\d mm apart \(< 10 predicted SDs = 0\.71 mm\)"
    ):
        calibrate(replace(exact, touches=touches), robot)


def test_separation_check_uses_the_positioning_noise_as_floor():
    # Exact touches of one point from two sets of directions: no spread, yet the same point.
    rng = np.random.default_rng(4)
    p_ref, p_Mtip = np.array([0.75, -0.05, 0.85]), np.array([0.0, 0.0, 0.15])
    one = reference_tip_estimate(touch_poses(rng, p_ref, p_Mtip, 3, 0.0), p_Mtip)
    two = reference_tip_estimate(touch_poses(rng, p_ref, p_Mtip, 3, 0.0), p_Mtip)
    with pytest.raises(DegenerateDataError, match=r"0\.000 mm apart"):
        check_separation(one, two)
    moved = reference_tip_estimate(touch_poses(rng, p_ref + np.array([0.0, 0.0, 1e-3]), p_Mtip, 3, 0.0), p_Mtip)
    assert abs(check_separation(one, moved) - 1e-3) < EXACT  # 1 mm > 0.71 mm: distinct points


def test_separation_bound_is_ten_predicted_sds_of_the_difference():
    # Exact touches (no spread: each trial SD floored at the positioning noise σ): the difference of
    # two 3-trial means has predicted 3D SD sqrt(2 · 3σ²/3) = 0.0707 mm, so the bound is 0.707 mm.
    rng = np.random.default_rng(5)
    p_ref, p_Mtip = np.array([0.75, -0.05, 0.85]), np.array([0.0, 0.0, 0.15])
    bound = MIN_SEPARATION_SIGMAS * np.sqrt(2 * 3 * TOUCH_SD_M**2 / 3)
    one = reference_tip_estimate(touch_poses(rng, p_ref, p_Mtip, 3, 0.0), p_Mtip)
    for factor, refused in ((0.9, True), (1.1, False)):
        other = p_ref + np.array([factor * bound, 0.0, 0.0])
        two = reference_tip_estimate(touch_poses(rng, other, p_Mtip, 3, 0.0), p_Mtip)
        if refused:
            with pytest.raises(DegenerateDataError, match=r"< 10 predicted SDs = 0\.71 mm"):
                check_separation(one, two)
        else:
            assert check_separation(one, two) == pytest.approx(factor * bound, rel=1e-9)


# --- tool rotation ----------------------------------------------------------------------------------


def axes_poses(y_move: np.ndarray, z_move: np.ndarray, R: np.ndarray | None = None) -> list[np.ndarray]:
    """Flange poses at p1, p2 = p1 + y_move, p3 = p1 + z_move (one orientation ``R``)."""
    R = np.eye(3) if R is None else R
    p1 = np.array([0.7, -0.1, 0.95])
    return [make_transform(R, p1), make_transform(R, p1 + y_move), make_transform(R, p1 + z_move)]


P_TIP = np.array([0.03, 0.0, 0.28])


def test_rotation_from_exact_moves_passes_and_reports_its_predicted_uncertainty():
    R_true = Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix()
    with warnings.catch_warnings():
        warnings.simplefilter("error", ConditioningWarning)
        rotation = tool_rotation(*axes_poses(0.02 * R_true[:, 1], 0.02 * R_true[:, 2]), P_TIP)
    assert np.abs(rotation.R_E_tool - R_true).max() < EXACT
    assert abs(rotation.axes_angle_deg - 90.0) < 1e-6
    # SD of the axes angle: √2 σ sqrt(1/L_y² + 1/L_z²) = √2 · 0.05 mm · √2 / 20 mm.
    assert np.isclose(rotation.axes_angle_sd_deg, np.degrees(2 * TOUCH_SD_M / 0.02), rtol=1e-9)


@pytest.mark.parametrize(
    ("y_length", "message"),
    [(0.0, r"p1->p2 \(y axis\) is 0\.000 mm"), (0.002, r"p1->p2 \(y axis\) is 2\.000 mm.* at least 2\.9 mm")],
)
def test_moves_too_short_for_a_direction_are_refused(y_length, message):
    with pytest.raises(DegenerateDataError, match=message):
        tool_rotation(*axes_poses(np.array([0.0, y_length, 0.0]), np.array([0.0, 0.0, 0.02])), P_TIP)


def test_short_moves_warn():
    # 8 mm: direction uncertain by 2σ/L = 0.72° > 0.5°; refused only below 2.9 mm.
    with pytest.warns(ConditioningWarning, match=r"only 8\.00 mm: its direction is uncertain by 0\.72 deg"):
        tool_rotation(*axes_poses(np.array([0.0, 0.008, 0.0]), np.array([0.0, 0.0, 0.02])), P_TIP)


@pytest.mark.parametrize(("off_deg", "refused"), [(3.0, False), (10.0, True), (90.0, True)])
def test_axes_far_from_perpendicular_warn_then_are_refused(off_deg, refused):
    # Predicted SD of the angle for two 20-mm moves: 0.286°; warn beyond 5 SDs (1.43°), refuse beyond 20 (5.73°).
    z = 0.02 * np.array([0.0, np.sin(np.radians(off_deg)), np.cos(np.radians(off_deg))])
    poses = axes_poses(np.array([0.0, 0.02, 0.0]), z)
    if refused:
        with pytest.raises(DegenerateDataError, match=rf"{90 - off_deg:.2f} deg apart, {off_deg:.2f} deg off"):
            tool_rotation(*poses, P_TIP)
    else:
        with pytest.warns(ConditioningWarning, match=rf"{off_deg:.2f} deg off perpendicular \(> 5 predicted SDs"):
            tool_rotation(*poses, P_TIP)


def test_zero_axes_moves_in_a_session_are_refused_naming_axes_csv(robot, exact):
    axes = {tool: dict(points) for tool, points in exact.axes.items()}
    axes["probe"]["p3"] = axes["probe"]["p1"]
    with pytest.raises(DegenerateDataError, match=r"probe: the move p1->p3 \(z axis\) is 0\.000 mm") as caught:
        calibrate(replace(exact, axes=axes), robot)
    assert caught.value.file == "axes.csv"


def test_rotation_uncertainty_predicts_the_spread_of_the_estimates():
    # The flange held at R_flange, the moves along its own y and z: in the flange frame the tool
    # frame is the identity.
    R_flange = Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix()
    rng = np.random.default_rng(5)
    rotation_errors, angle_errors, rotation_sd, angle_sd = [], [], [], []
    for _ in range(DRAWS):
        poses = axes_poses(0.02 * R_flange[:, 1], 0.02 * R_flange[:, 2], R_flange)
        for T in poses:  # each point off by the positioning noise
            T[:3, 3] += rng.normal(scale=TOUCH_SD_M, size=3)
        result = tool_rotation(*poses, P_TIP)
        rotation_errors.append(angle_between(result.R_E_tool, np.eye(3)))
        angle_errors.append(result.axes_angle_deg - 90.0)
        rotation_sd.append(np.radians(result.rotation_sd_deg))
        angle_sd.append(result.axes_angle_sd_deg)
    assert LOW < ratio(np.array(rotation_errors), np.array(rotation_sd)) < HIGH
    assert LOW < ratio(np.array(angle_errors), np.array(angle_sd)) < HIGH


# --- registration (eq. 9) ---------------------------------------------------------------------------

SPACING = np.array([0.19e-3, 0.19e-3])
T_PROBE_IMAGE = make_transform(Rotation.from_rotvec([1.5, 0.1, -0.2]).as_matrix(), [-0.1, 0.01, 0.02])


def pixels(n: int = 40, seed: int = 0) -> np.ndarray:
    """``(n, 2)`` random pixels over the middle of a 1080 x 720 image (no symmetry)."""
    return np.random.default_rng(seed).uniform([250, 100], [850, 650], size=(n, 2))


def probe_points(uv: np.ndarray, spacing=SPACING, T=T_PROBE_IMAGE) -> np.ndarray:
    return transform_points(T, image_to_probe.image_points(uv, spacing))


@pytest.mark.parametrize("method", image_to_probe.METHODS)
def test_exact_registration_passes_and_recovers_the_truth(method):
    uv = pixels()
    with warnings.catch_warnings():
        warnings.simplefilter("error", ConditioningWarning)
        calibration = image_to_probe.fit(method, uv, probe_points(uv), SPACING, T_PROBE_IMAGE)
    assert np.abs(calibration.T_Ptip_I - T_PROBE_IMAGE).max() < EXACT
    assert np.abs(calibration.spacing_m - SPACING).max() < 1e-15
    assert calibration.uncertainty.reach_sd_m < EXACT


@pytest.mark.parametrize("method", ["kabsch", "similarity", "scaled_uv"])
def test_registration_uncertainty_predicts_the_spread_of_the_estimates(method):
    # Isotropic noise on the probe-frame points: the noise model the propagation assumes.
    uv, sigma = pixels(30), 2e-4
    rng = np.random.default_rng(8)
    errors = {"rotation": [], "origin": [], "spacing": [], "samples": []}
    predicted = {"rotation": [], "origin": [], "spacing": [], "samples": []}
    p_I = image_to_probe.image_points(uv, SPACING)
    for _ in range(DRAWS):
        noisy = probe_points(uv) + rng.normal(scale=sigma, size=(len(uv), 3))
        calibration = image_to_probe.fit(method, uv, noisy, SPACING)
        u = calibration.uncertainty
        errors["rotation"].append(angle_between(calibration.T_Ptip_I[:3, :3], T_PROBE_IMAGE[:3, :3]))
        predicted["rotation"].append(np.radians(u.rotation_sd_deg))
        errors["origin"].append(np.linalg.norm(calibration.T_Ptip_I[:3, 3] - T_PROBE_IMAGE[:3, 3]))
        predicted["origin"].append(u.origin_sd_m)
        mapped = transform_points(calibration.T_Ptip_I, calibration.image_points(uv))
        errors["samples"].append(np.sqrt(np.mean(np.sum((mapped - transform_points(T_PROBE_IMAGE, p_I)) ** 2, axis=1))))
        predicted["samples"].append(u.samples_sd_m)
        errors["spacing"].extend(calibration.spacing_m - SPACING)
        predicted["spacing"].extend(u.spacing_sd_m)
    for figure in ("rotation", "origin", "samples") + (("spacing",) if method != "kabsch" else ()):
        assert LOW < ratio(np.array(errors[figure]), np.array(predicted[figure])) < HIGH, figure


def test_all_samples_at_one_robot_pose_are_refused(robot, exact):
    # Every image taken at the first sample's joints: the needle tips in the probe frame coincide.
    one = replace(exact, samples_q=np.repeat(exact.samples_q[:1], len(exact.samples_q), axis=0))
    with pytest.raises(
        DegenerateDataError, match=r"probe frame \(eq\. 8\) spread only 0\.000 mm .* one robot pose"
    ) as caught:
        calibrate(one, robot, methods=("kabsch",))
    assert caught.value.file == "samples.csv"


def test_pixels_without_spread_across_are_refused():
    uv = pixels(40)
    uv[:, 1] = 360.0 + 0.3 * np.where(np.arange(40) % 2, 1.0, -1.0)  # 0.3 px across a 600 px line
    with pytest.raises(DegenerateDataError, match=r"needle tips spread only 0\.30 px .* at least 3\.95 px"):
        image_to_probe.fit("kabsch", uv, probe_points(uv), SPACING)


def test_thin_sample_sets_warn_before_they_are_refused():
    # 10 samples 16 px (3 mm) across: the tilt about their long axis is uncertain by
    # σ/(√N s) = 0.19 mm / (√10 · 3 mm) = 1.1°, about 1 mm at 50 mm: warns (> 0.5 mm), not refused (< 2 mm).
    rng = np.random.default_rng(3)
    uv = np.column_stack([np.linspace(250, 850, 10), 360 + rng.choice([-16.0, 16.0], size=10)])
    with pytest.warns(ConditioningWarning, match=r"kabsch: .* poorly determined: predicted error 1\.\d+ mm at 50 mm"):
        image_to_probe.fit("kabsch", uv, probe_points(uv), SPACING)


def test_zero_similarity_scale_is_refused():
    src = image_to_probe.image_points(pixels(10), SPACING)
    with pytest.raises(
        DegenerateDataError, match=r"similarity scale comes out \S+ \(target points spread \S+ mm RMS\)"
    ):
        registration.similarity(src, np.repeat(src[:1], 10, axis=0))


@pytest.mark.parametrize(("scale", "refused"), [(1.12, False), (2.0, True)])
def test_implausible_spacings_warn_then_are_refused(scale, refused):
    uv = pixels()
    target = probe_points(uv, SPACING * scale)
    if refused:
        with pytest.raises(DegenerateDataError, match=r"spacing 0\.38 x 0\.38 mm/px .* more than a factor 1\.5"):
            image_to_probe.fit("similarity", uv, target, SPACING)
    else:
        with pytest.warns(ConditioningWarning, match=r"off by 12\.0 % \(> 10 %"):
            image_to_probe.fit("similarity", uv, target, SPACING)


def test_spacing_beyond_the_plausible_range_by_chance_is_not_refused():
    # A fitted spacing beyond the plausible factor 1.5 is refused only when it lies more than 3 of its
    # predicted SDs outside: noisy data (8 samples, 6 mm per coordinate) at a factor 1.55 come out
    # 1.58 ± 0.055, 1.5 SD out: reported (with warnings), not refused; data at a factor 2 with 4 mm of
    # noise, 14 SDs out, are refused.
    uv = pixels(8, seed=2)
    noisy = probe_points(uv, SPACING * 1.55) + np.random.default_rng(0).normal(scale=6e-3, size=(8, 3))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConditioningWarning)
        calibration = image_to_probe.fit("similarity", uv, noisy, SPACING)
    factor = calibration.spacing_m[0] / SPACING[0]
    factor_sd = calibration.uncertainty.spacing_sd_m[0] / SPACING[0]
    assert 0 < factor - 1.5 < 3 * factor_sd
    precise = probe_points(uv, SPACING * 2.0) + np.random.default_rng(0).normal(scale=4e-3, size=(8, 3))
    with pytest.raises(DegenerateDataError, match=r"more than a factor 1\.5 \(beyond 3 predicted SDs\)"):
        image_to_probe.fit("similarity", uv, precise, SPACING)


def test_leave_one_out_refuses_a_fold_that_loses_the_spread(robot):
    # Ten samples on a line (0.1 px across) and one 300 px off it: the full set fixes the plane,
    # the fold without that one sample does not; no Table II row may come from such a fold.
    uv = np.column_stack([np.linspace(300, 800, 11), np.full(11, 300.0)])
    uv[:10, 1] += 0.1 * np.where(np.arange(10) % 2, 1.0, -1.0)
    uv[10] = [550.0, 600.0]
    T_R_EL = np.repeat(np.eye(4)[None], 11, axis=0)
    T_EL_Ptip = np.eye(4)
    p_Ptip = probe_points(uv)
    T_R_ER = make_transform(np.eye(3), p_Ptip)  # the needle tip at the flange origin reaches each point
    image_to_probe.fit("kabsch", uv, p_Ptip, SPACING)  # all 11: accepted
    with pytest.raises(
        DegenerateDataError,
        match=r"leave-one-out fold without sample #11: .* spread only 0\.10 px .* at least 7\.91 px",
    ):
        image_to_probe.leave_one_out("kabsch", uv, T_R_ER, T_R_EL, np.zeros(3), T_EL_Ptip, SPACING)


# --- ICP: independent of the nominal image frame ----------------------------------------------------


@pytest.fixture(scope="module", params=[90, 180])
def turned(request, robot):
    """A noise-free session whose probe sits turned about its shaft (z) from the URDF's nominal."""
    base = default_truth(robot)
    turn = make_transform(Rotation.from_euler("z", request.param, degrees=True).as_matrix(), np.zeros(3))
    truth = replace(base, T_Ptip_I=turn @ base.T_Ptip_I)
    return truth, exact_session(robot, truth)


def test_icp_recovers_a_probe_turned_from_the_nominal_and_says_the_nominal_is_off(robot, turned):
    truth, session = turned
    with pytest.warns(ConditioningWarning, match=r"icp: the fitted image frame is .* nominal image frame is off"):
        result = calibrate(asymmetric(session), robot, methods=("icp",))
    assert np.abs(result.image["icp"].T_Ptip_I - truth.T_Ptip_I).max() < EXACT
    assert result.loocv["icp"].max_mm < 1e-6  # mm: every fold found the truth too


def test_icp_refuses_a_symmetric_pattern_the_nominal_cannot_resolve(robot, turned):
    # The full 4 x 4 grid repeats at every probe pose: turned over, it matches itself, so four fits
    # have zero residual and the nominal, 90° or 180° off, cannot choose among them.
    _, session = turned
    with pytest.raises(DegenerateDataError, match=r"icp: 4 fits match the samples equally well"):
        calibrate(session, robot, methods=("icp",))


def test_icp_refuses_the_mirror_twin_a_wrong_nominal_picks():
    # A 3 x 3 grid mirrored about its middle column is itself; the nominal sits exactly on that twin,
    # so the tie-break picks it and it is within 10°/10 mm of the nominal: only the recorded pairs
    # (each pixel with its own probe-frame point) show that it is wrong.
    uv = np.array([(u, v) for u in (400.0, 500.0, 600.0) for v in (300.0, 400.0, 500.0)])
    centre_x = 500.0 * SPACING[0]
    mirror = make_transform(np.diag([-1.0, 1.0, -1.0]), [2 * centre_x, 0.0, 0.0])
    with pytest.raises(DegenerateDataError, match=r"icp: its fit puts the samples on other samples' probe-frame"):
        image_to_probe.fit("icp", uv, probe_points(uv), SPACING, T_PROBE_IMAGE @ mirror)
    # The right nominal gives the truth.
    calibration = image_to_probe.fit("icp", uv, probe_points(uv), SPACING, T_PROBE_IMAGE)
    assert np.abs(calibration.T_Ptip_I - T_PROBE_IMAGE).max() < EXACT


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(5, 60))
def test_icp_finds_the_truth_from_any_prior(seed, n):
    # Random pixels have no symmetry: the best fit is unique, so the prior (here anything) does not matter.
    rng = np.random.default_rng(seed)
    T_true = make_transform(
        Rotation.random(random_state=rng.integers(2**32)).as_matrix(), rng.normal(scale=0.2, size=3)
    )
    src = image_to_probe.image_points(rng.uniform([0, 0], [1080, 720], size=(n, 2)), SPACING)
    dst = transform_points(T_true, src)[rng.permutation(n)]
    prior = make_transform(Rotation.random(random_state=rng.integers(2**32)).as_matrix(), rng.normal(scale=0.5, size=3))
    result = registration.icp_global(src, dst, prior)
    assert np.abs(result.T - T_true).max() < EXACT


# --- pivot ------------------------------------------------------------------------------------------

P_TOOL_TIP, P_PIVOT = np.array([0.01, -0.02, 0.15]), np.array([0.7, 0.1, 0.9])


def pivot_poses(rotvecs: np.ndarray, rng=None, sigma: float = 0.0) -> np.ndarray:
    """Poses of a pointer held tip-down and turned by ``rotvecs (N, 3)`` about its fixed tip."""
    R = (Rotation.from_euler("x", 180, degrees=True) * Rotation.from_rotvec(rotvecs)).as_matrix()
    t = P_PIVOT - np.einsum("nij,j->ni", R, P_TOOL_TIP)
    if sigma:
        t = t + rng.normal(scale=sigma, size=t.shape)
    return make_transform(R, t)


def test_exact_pivot_passes_and_recovers_the_tip():
    rotvecs = np.random.default_rng(1).normal(scale=0.4, size=(30, 3))
    with warnings.catch_warnings():
        warnings.simplefilter("error", ConditioningWarning)
        result = pivot_algebraic(pivot_poses(rotvecs))
    assert np.abs(result.p_marker_tip - P_TOOL_TIP).max() < EXACT and result.tip_sd < EXACT
    assert result.rotation_spread_deg > 15.0


@pytest.mark.parametrize("fit", [pivot_algebraic, pivot_robust])
def test_pivot_uncertainty_predicts_the_spread_of_the_estimates(fit):
    rng = np.random.default_rng(9)
    rotvecs = rng.normal(scale=0.3, size=(25, 3))
    tip_errors, pivot_errors, tip_sd, pivot_sd = [], [], [], []
    for _ in range(DRAWS):
        result = fit(pivot_poses(rotvecs, rng, 3e-4))
        tip_errors.append(np.linalg.norm(result.p_marker_tip - P_TOOL_TIP))
        pivot_errors.append(np.linalg.norm(result.p_ref_pivot - P_PIVOT))
        tip_sd.append(result.tip_sd)
        pivot_sd.append(result.pivot_sd)
    assert LOW < ratio(np.array(tip_errors), np.array(tip_sd)) < HIGH
    assert LOW < ratio(np.array(pivot_errors), np.array(pivot_sd)) < HIGH


def test_pivot_noise_estimate_is_unbiased_with_its_degrees_of_freedom():
    # Noise σ on each pose's position enters the linear equations [R_i  −I] x = −t_i directly: the
    # residual sum of squares is σ² χ² with 3N − 6 degrees of freedom (6 unknowns), for few poses too.
    rng = np.random.default_rng(14)
    sigma = 3e-4
    for n in (4, 6, 10):
        rotvecs = rng.normal(scale=0.4, size=(n, 3))
        ratios = [(pivot_algebraic(pivot_poses(rotvecs, rng, sigma)).noise_sd / sigma) ** 2 for _ in range(DRAWS)]
        assert_unbiased_variance(ratios, 3 * n - 6)


def test_robust_pivot_flags_no_pose_of_clean_gaussian_noise():
    # The robust variant flags poses whose 3D residual exceeds 3 robust SDs of the 3D residual:
    # 3 × √3 × its per-axis scale, 1.4826 × median‖r‖/√3 (for Gaussian noise σ per axis, the median of
    # ‖r‖ is σ·sqrt(median χ²_3)). On clean noise a pose is then flagged with probability
    # P(χ²_3 > (3 √3 k)²), k = scale/σ: too small to flag any of many poses.
    rng = np.random.default_rng(15)
    sigma, n = 3e-4, 50_000
    k = 1.4826 * np.sqrt(chi2.ppf(0.5, 3)) / np.sqrt(3.0)
    p_false = chi2.sf((3.0 * np.sqrt(3.0) * k) ** 2, 3)
    most = binom.isf(1e-4, n, p_false)  # the false flags of n poses, at the 1e-4 level
    result = pivot_robust(pivot_poses(rng.normal(scale=0.3, size=(n, 3)), rng, sigma))
    assert (~result.inliers).sum() <= most
    assert result.noise_sd == pytest.approx(sigma, rel=0.01)


@pytest.mark.parametrize(
    ("rotvecs", "spread"),
    [
        # three poses 0.06° apart
        (np.radians([[0.0, 0.0, 0.0], [0.06, 0.0, 0.0], [0.0, 0.06, 0.0]]), r"0\.02\d* deg"),
        # turned ±30° about one axis only: the tip is undetermined along it
        (np.column_stack([np.zeros(20), np.zeros(20), np.radians(np.linspace(-30, 30, 20))]), r"0 deg"),
        # ±30° about one axis with a 0.5° wobble about another
        (
            np.column_stack(
                [np.radians(0.5) * np.sin(np.arange(20)), np.zeros(20), np.radians(np.linspace(-30, 30, 20))]
            ),
            r"0\.3\d* deg",
        ),
    ],
    ids=["three-poses-0.06-deg", "one-axis", "nearly-one-axis"],
)
def test_pivot_rotations_that_do_not_determine_the_tip_are_refused(rotvecs, spread):
    with pytest.raises(DegenerateDataError, match=rf"orientations do not vary enough .* rotation spread {spread}"):
        pivot_algebraic(pivot_poses(rotvecs))


def test_pivot_rotations_in_the_grey_zone_warn():
    # ±4° about every axis: spread ≈ 3°, a pose error reaches the tip ~20-fold (> 10): warns, not refused (< 50).
    rotvecs = np.radians(np.random.default_rng(4).uniform(-4, 4, size=(30, 3)))
    with pytest.warns(ConditioningWarning, match=r"tip is poorly determined: rotation spread [2-4]\.\d+ deg"):
        pivot_algebraic(pivot_poses(rotvecs))


def test_noisy_but_well_spread_samples_warn_and_are_not_refused():
    # 3 mm of noise per coordinate: the geometry determines the fit (refusals come from the design at
    # the stated 1-px annotation noise), the residual says it is poor (~0.9 mm at 50 mm): a warning.
    uv = pixels(40)
    noisy = probe_points(uv) + np.random.default_rng(6).normal(scale=3e-3, size=(40, 3))
    with pytest.warns(ConditioningWarning, match=r"poorly determined: .* mm residual noise per coordinate"):
        calibration = image_to_probe.fit("kabsch", uv, noisy, SPACING)
    assert 2.5e-3 < calibration.uncertainty.noise_sd_m < 3.5e-3  # σ̂ estimates the 3 mm
