"""Mutation audit of the stated uncertainties: every degree-of-freedom count, SD, inflation and
threshold of the noise models must have a test that fails when it is wrong.

Run: ``.venv/bin/python benchmarks/mutants.py [NAME ...] [--jobs N] [--list]`` (``make mutants``;
default: every mutant of :data:`MUTANTS`, one at a time).

Each row of :data:`MUTANTS` is a single-line change to an estimator (file under ``src/brachycal``,
the exact original snippet, its replacement) and the tests that must catch it. For each mutant the
source tree ``src/`` is copied to a temporary folder, the snippet replaced there (it must occur
exactly once), and the named tests run against the copy (``PYTHONPATH`` pointing at it): the
working tree is never edited, so runs may go in parallel. A mutant is *caught* when the tests fail
(pytest exit 1); it *survives* when they pass. Before the mutants, the same tests run against an
unmutated copy and must pass (else a "caught" would mean nothing). One row per mutant is printed;
the exit status is non-zero if any mutant survives or errs (or the baseline fails).

``tests/test_mutants.py`` keeps the table from rotting silently: each snippet occurs exactly once in
its file, and each named test exists.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "src" / "brachycal"
#: Bundled data the package reads from beside ``src/`` in a source tree.
BUNDLED = ("urdf", "examples")
#: Longest a mutant's tests may run, seconds (a mutant that loops forever counts as caught by it).
TIMEOUT_S = 600.0


@dataclass(frozen=True)
class Mutant:
    """One single-line change and the tests that must catch it.

    Attributes:
        name: short identifier (``--list`` shows them; arguments select by it).
        file: path under ``src/brachycal``.
        original: exact snippet of that file (occurs exactly once).
        replacement: what it becomes.
        tests: pytest node ids (``tests/test_x.py::test_y``) that must fail on the mutant.
        why: what the change breaks.
    """

    name: str
    file: str
    original: str
    replacement: str
    tests: tuple[str, ...]
    why: str


COND = "tests/test_conditioning.py::"
ORIENT = "tests/test_plus_orientation.py::"
REG = "tests/test_registration.py::"
PIV = "tests/test_pivot.py::"
TEMP = "tests/test_temporal.py::"
ROBOT = "tests/test_robot_identification.py::"
CHAIN = "tests/test_chain.py::"
ARM = "tests/test_arm_fit_noise.py::"
LANDING = "tests/test_landing_prediction.py::test_the_predicted_landing_error_is_honest_on_non_default_twins"
TOUCH = "tests/test_touch_identification.py::"
TRACK = "tests/test_tracker_identification.py::"
EVID = "tests/test_evidence_search.py::"
HTP = "tests/test_hostile_trus_probe.py::test_stepper_probe_refusals"
HST = "tests/test_hostile_stepper.py::test_stepper_calibrate_refuses"
HOSTILE_ROBOT = "tests/test_hostile_robot.py::"
HTML = "tests/test_html_report.py::"

MUTANTS: tuple[Mutant, ...] = (
    # --- tool tips (eqs. 4-6) ---------------------------------------------------------------------
    Mutant(
        "tips-dof",
        "calibration/sequential/tool_tips.py",
        "/ (3 * (len(points) - 1))",
        "/ (3 * len(points))",
        (COND + "test_tip_noise_estimate_is_unbiased_with_its_degrees_of_freedom",),
        "the trials' SD over 3T instead of 3(T-1) degrees of freedom: 18 % too small with 3 trials",
    ),
    Mutant(
        "tips-reference-over-T",
        "calibration/sequential/tool_tips.py",
        "return TipEstimate(points.mean(axis=0), points, sigma, sigma**2 * np.eye(3) / len(points))",
        "return TipEstimate(points.mean(axis=0), points, sigma, sigma**2 * np.eye(3))",
        (COND + "test_tip_uncertainty_predicts_the_spread_of_the_estimates",),
        "the reference tip's covariance not divided by the trials",
    ),
    Mutant(
        "tips-reference-term",
        "calibration/sequential/tool_tips.py",
        "cov = sigma**2 * np.eye(3) / len(points) + M @ reference.cov @ M.T",
        "cov = sigma**2 * np.eye(3) / len(points)",
        (COND + "test_tool_tip_intervals_cover_the_truth_at_their_level",),
        "the reference tip's error left out of the tool tip's covariance",
    ),
    Mutant(
        "tips-separation-3d",
        "calibration/sequential/tool_tips.py",
        "variance = sum(3 * max(tip.sigma_m, TOUCH_SD_M) ** 2",
        "variance = sum(max(tip.sigma_m, TOUCH_SD_M) ** 2",
        (COND + "test_separation_bound_is_ten_predicted_sds_of_the_difference",),
        "the separation check's 3D variance counted on one axis (bound √3 too small)",
    ),
    # --- tool rotation (eq. 7) --------------------------------------------------------------------
    Mutant(
        "rotation-angle-sd",
        "calibration/sequential/tool_rotation.py",
        "angle_sd = float(np.degrees(np.sqrt(2.0) * point_sd_m * np.sqrt(np.sum(1.0 / moves**2))))",
        "angle_sd = float(np.degrees(point_sd_m * np.sqrt(np.sum(1.0 / moves**2))))",
        (COND + "test_rotation_uncertainty_predicts_the_spread_of_the_estimates",),
        "the axes angle's SD without the √2 of two noisy end points",
    ),
    Mutant(
        "rotation-sd-sqrt",
        "calibration/sequential/tool_rotation.py",
        "return float(sigma * np.sqrt(np.trace(J @ J.T)))",
        "return float(sigma * np.sqrt(np.trace(J @ J.T) / 3))",
        (COND + "test_rotation_uncertainty_predicts_the_spread_of_the_estimates",),
        "the rotation's RMS angle per axis instead of in 3D",
    ),
    Mutant(
        "rotation-shortest-move",
        "calibration/sequential/tool_rotation.py",
        "shortest = 2 * point_sd_m / MAX_DIRECTION_SD_RAD",
        "shortest = point_sd_m / MAX_DIRECTION_SD_RAD",
        (COND + "test_moves_too_short_for_a_direction_are_refused",),
        "the shortest move from a direction SD of σ/L instead of 2σ/L",
    ),
    Mutant(
        "rotation-direction-sd",
        "calibration/sequential/tool_rotation.py",
        "direction_sd_deg=np.degrees(2 * point_sd_m / moves),",
        "direction_sd_deg=np.degrees(point_sd_m / moves),",
        (COND + "test_exact_session_passes_every_check_and_predicts_no_uncertainty",),
        "the reported direction SD of a move without the two noisy end points",
    ),
    # --- registration (eq. 9) ---------------------------------------------------------------------
    Mutant(
        "registration-dof",
        "calibration/sequential/registration.py",
        "dof = 3 * len(src) - n_params",
        "dof = 3 * len(src)",
        (REG + "test_fit_noise_estimate_is_unbiased_with_its_degrees_of_freedom",),
        "the residual's degrees of freedom without the fitted parameters",
    ),
    Mutant(
        "registration-similarity-reflection",
        "calibration/sequential/registration.py",
        "D = np.array([1.0, 1.0, d])",
        "D = np.array([1.0, 1.0, 1.0])",
        (REG + "test_similarity_of_a_mirror_image_is_the_best_proper_fit",),
        "the similarity's reflection guard dropped: a mirror image comes back as a reflection",
    ),
    Mutant(
        "registration-similarity-scale",
        "calibration/sequential/registration.py",
        "scale = float(np.sum(sigma * D) / np.sum(a**2))",
        "scale = float(np.sum(sigma) / np.sum(a**2))",
        (REG + "test_similarity_of_a_mirror_image_is_the_best_proper_fit",),
        "the similarity's scale from the reflection's singular values",
    ),
    Mutant(
        "registration-scale-column",
        "calibration/sequential/registration.py",
        "J[:, :, 6] = p_src @ R.T",
        "J[:, :, 6] = p_src",
        (COND + "test_registration_uncertainty_predicts_the_spread_of_the_estimates[similarity]",),
        "the similarity scale's Jacobian column not rotated into the target frame",
    ),
    Mutant(
        "registration-uv-column",
        "calibration/sequential/registration.py",
        "J[:, :, 7] = p_src[:, 1:2] * R[:, 1]",
        "J[:, :, 7] = p_src[:, 1:2] * R[:, 0]",
        (COND + "test_registration_uncertainty_predicts_the_spread_of_the_estimates[scaled_uv]",),
        "the v spacing's Jacobian column along the image's u axis",
    ),
    # --- image to probe (eq. 9 checks) ------------------------------------------------------------
    Mutant(
        "image-spacing-3sd",
        "calibration/sequential/image_to_probe.py",
        "np.any(outside > 3 * factor_sd)",
        "np.any(outside > 0)",
        (COND + "test_spacing_beyond_the_plausible_range_by_chance_is_not_refused",),
        "a noisy fit's spacing refused when only its noise puts it beyond the plausible range",
    ),
    Mutant(
        "image-spacing-sd-multiple",
        "calibration/sequential/image_to_probe.py",
        "np.any(outside > 3 * factor_sd)",
        "np.any(outside > 30 * factor_sd)",
        (COND + "test_spacing_beyond_the_plausible_range_by_chance_is_not_refused",),
        "an implausible spacing accepted because it is noisy",
    ),
    Mutant(
        "image-samples-sd",
        "calibration/sequential/image_to_probe.py",
        "samples_sd_m=fit_unc.noise_sd_m * float(np.sqrt(fit_unc.cov_unit.shape[0] / len(p_I))),",
        "samples_sd_m=fit_unc.noise_sd_m * float(np.sqrt(3 * fit_unc.cov_unit.shape[0] / len(p_I))),",
        (COND + "test_registration_uncertainty_predicts_the_spread_of_the_estimates[kabsch]",),
        "the samples' mean 3D SD with the hat matrix's trace counted per axis",
    ),
    Mutant(
        "image-spread-sqrt-n",
        "calibration/sequential/image_to_probe.py",
        "least = REACH_M * sigma_m / (np.sqrt(n) * MAX_REACH_SD_M)",
        "least = REACH_M * sigma_m / MAX_REACH_SD_M",
        (COND + "test_pixels_without_spread_across_are_refused",),
        "the least spread without the √N the samples average",
    ),
    # --- pivot ------------------------------------------------------------------------------------
    Mutant(
        "pivot-dof",
        "calibration/phantom/pivot.py",
        "max(3 * n - 6, 1)",
        "max(3 * n, 1)",
        (COND + "test_pivot_noise_estimate_is_unbiased_with_its_degrees_of_freedom",),
        "the pivot residual's degrees of freedom without the 6 parameters",
    ),
    Mutant(
        "pivot-robust-threshold",
        "calibration/phantom/pivot.py",
        "inliers = residuals <= outlier_threshold * np.sqrt(3.0) * scale",
        "inliers = residuals <= outlier_threshold * scale",
        (COND + "test_robust_pivot_flags_no_pose_of_clean_gaussian_noise",),
        "the robust threshold on the 3D residual with the per-axis scale (√3 too tight)",
    ),
    Mutant(
        "pivot-robust-scale",
        "calibration/phantom/pivot.py",
        "scale = max(1.4826 * float(np.median(start.residuals)) / np.sqrt(3.0), 1e-12)",
        "scale = max(float(np.median(start.residuals)) / np.sqrt(3.0), 1e-12)",
        (COND + "test_robust_pivot_flags_no_pose_of_clean_gaussian_noise",),
        "the robust scale without the MAD's consistency factor",
    ),
    Mutant(
        "pivot-covariance",
        "calibration/phantom/pivot.py",
        "cov = noise**2 * np.linalg.inv(A_in.T @ A_in)",
        "cov = noise * np.linalg.inv(A_in.T @ A_in)",
        (COND + "test_pivot_uncertainty_predicts_the_spread_of_the_estimates[pivot_algebraic]",),
        "the covariance scaled by the SD instead of the variance",
    ),
    Mutant(
        "pivot-tip-sd",
        "calibration/phantom/pivot.py",
        "tip_sd=float(np.sqrt(np.trace(cov[:3, :3]))),",
        "tip_sd=float(np.sqrt(np.max(np.diag(cov[:3, :3])))),",
        (COND + "test_pivot_uncertainty_predicts_the_spread_of_the_estimates[pivot_algebraic]",),
        "the tip's 3D SD from its worst axis alone",
    ),
    # --- temporal ---------------------------------------------------------------------------------
    Mutant(
        "temporal-inflation",
        "calibration/temporal.py",
        "inflation = (1 + rho) / (1 - rho)",
        "inflation = 1.0",
        (
            TEMP + "test_stated_sd_accounts_for_autocorrelated_noise",
            TEMP + "test_lag_on_plus_water_tank_recording_is_within_5_ms_of_plus",
        ),
        "the lag's SD without the residuals' autocorrelation (PLUS's recording: 6.8 -> 2.3 ms)",
    ),
    Mutant(
        "temporal-inflation-sqrt",
        "calibration/temporal.py",
        "inflation = (1 + rho) / (1 - rho)",
        "inflation = np.sqrt((1 + rho) / (1 - rho))",
        (TEMP + "test_stated_sd_accounts_for_autocorrelated_noise",),
        "the autocorrelation's variance inflation applied as an SD inflation",
    ),
    Mutant(
        "temporal-negative-rho",
        "calibration/temporal.py",
        "rho = float(np.clip(rho, 0.0, 0.95))",
        "rho = float(np.clip(rho, -0.95, 0.95))",
        (TEMP + "test_negative_autocorrelation_does_not_shrink_the_sd",),
        "a negative residual autocorrelation trusted to shrink the SD",
    ),
    Mutant(
        "temporal-effective-samples",
        "calibration/temporal.py",
        "return sd, float(np.sqrt(sigma2)), float(beta), n / inflation",
        "return sd, float(np.sqrt(sigma2)), float(beta), n * inflation",
        (TEMP + "test_stated_sd_accounts_for_autocorrelated_noise",),
        "the effective sample count inflated instead of deflated by the autocorrelation",
    ),
    Mutant(
        "temporal-dof",
        "calibration/temporal.py",
        "sigma2 = float(residual @ residual) / (n - 3)",
        "sigma2 = float(residual @ residual) / n",
        (TEMP + "test_residual_sd_is_unbiased_with_three_fitted_parameters",),
        "the alignment residual's variance without the 3 fitted parameters",
    ),
    # --- robot identification ---------------------------------------------------------------------
    Mutant(
        "identification-leverages",
        "calibration/robot/arm_fit.py",
        'h = np.einsum("ij,jk,ik->i", J, _inverse(A), J)',
        'h = np.einsum("ij,jk,ik->i", J, np.linalg.pinv(J.T @ J), J)',
        (ROBOT + "test_identified_noise_levels_count_the_priors_share_of_the_leverage",),
        "the MAP's noise levels with least-squares leverages (the prior's share ignored)",
    ),
    Mutant(
        "arm-fit-noise-pooling",
        "calibration/robot/arm_fit.py",
        "if rules.ruled[g] and dof[g] < MIN_NOISE_DOF:",
        "if False:",
        (ARM + "test_a_group_with_too_few_degrees_of_freedom_takes_its_partners_level",),
        "a group with a noise rule estimating its level from too few degrees of freedom of its own",
    ),
    Mutant(
        "tilt-prior-turn-variance",
        "calibration/robot_accuracy.py",
        "+ 2 * self.rotation_sd_rad**2 * along",
        "+ self.rotation_sd_rad**2 * along",
        (TOUCH + "test_tilt_prior_is_across_the_axis_and_leaves_the_turn_about_it",),
        "the turn about the axis without its zero offset's share (variance not doubled) once the tilt is apart",
    ),
    Mutant(
        "evidence-translation-floor",
        "calibration/robot/evidence.py",
        "if not (np.log(EVIDENCE_FLOOR_M) <= z[0] <= np.log(MAX_ROBOT_TRANSLATION_SD_M))",
        "if not (z[0] <= np.log(MAX_ROBOT_TRANSLATION_SD_M))",
        (EVID + "test_search_stops_at_the_floor_where_the_data_want_no_correction",),
        "the evidence search walking the translation SD below its floor, towards zero",
    ),
    Mutant(
        "tracker-fold-prior-leak",
        "calibration/robot/tracker.py",
        "fit = fit_tracker(data.subset(keep), model, accuracy, selection=selection, prior=prior)",
        "fit = fit_tracker(data, model, accuracy, selection=selection, prior=prior)",
        (TRACK + "test_leave_one_out_predicts_each_posture_without_it",),
        "a leave-one-out fold fitted with the posture it predicts",
    ),
    Mutant(
        "touch-folder-one-point-twice",
        "data/formats/touches.py",
        "        if k in by_number:",
        "        if False:",
        (TOUCH + "test_reader_refuses_in_one_line_naming_the_place",),
        "hole_1.csv and hole_01.csv both read as point 1 (one silently dropped)",
    ),
    Mutant(
        "dynamics-joint-names",
        "calibration/robot/arm_fit.py",
        "    if missing:",
        "    if False:",
        (
            TOUCH + "test_dynamics_of_another_arm_are_refused_naming_the_option",
            HOSTILE_ROBOT + "test_refused_in_one_line_with_nothing_written[dynamics-of-another-arm]",
        ),
        "--dynamics of another arm (none of its joints the arm's) taken: no moments, compliance silently dropped",
    ),
    Mutant(
        "dynamics-joint-origins",
        "calibration/robot/arm_fit.py",
        "if offset > SAME_ORIGIN_M or turn > SAME_ORIGIN_RAD or axis > SAME_ORIGIN_RAD:",
        "if False:",
        (TOUCH + "test_dynamics_with_the_arm_s_joint_names_but_another_geometry_are_refused",),
        "--dynamics of another arm under the arm's joint names taken: moments in another arm's frames",
    ),
    Mutant(
        "dynamics-masses",
        "calibration/robot/arm_fit.py",
        "    if not moved > 0:",
        "    if False:",
        (HOSTILE_ROBOT + "test_refused_in_one_line_with_nothing_written[dynamics-without-masses]",),
        "--dynamics without masses taken: no joint loaded, compliance silently dropped",
    ),
    Mutant(
        "touches-headline-written-urdf",
        "calibration/robot/touches.py",
        '"written_urdf_mm": mean(self.geometry_only),',
        '"written_urdf_mm": mean(self.identified),',
        (TOUCH + "test_headline_is_the_written_urdf_s_held_out_scatter",),
        "the headline taken from the compliance fit, which the written URDF cannot hold",
    ),
    Mutant(
        "touches-choice-se-rule",
        "calibration/robot/touches.py",
        "            if mean < -se:",
        "            if True:",
        (TOUCH + "test_choice_leaves_the_default_only_for_a_setting_better_by_more_than_its_se",),
        "a setting replaces the one chosen before it whatever its cross-validated error",
    ),
    Mutant(
        "touches-cv-place-leak",
        "calibration/robot/touches.py",
        "others = [p for j, p in enumerate(places) if j != i]",
        "others = list(places)",
        (TOUCH + "test_cross_validation_over_places_predicts_each_from_the_others_only",),
        "a left-out place predicted by a fit that used it",
    ),
    Mutant(
        "identification-prior-sd",
        "calibration/robot/arm_fit.py",
        "return np.sqrt(np.diag(accuracy.covariance(robot)))",
        "return np.diag(accuracy.covariance(robot))",
        (ROBOT + "test_stated_uncertainty_includes_the_identified_robot",),
        "the prior's SDs given as variances (a prior 1e4 times too tight)",
    ),
    Mutant(
        "identification-consider-noise",
        "calibration/robot/identification.py",
        "noise = C_tt - sensitivity @ C_cc @ sensitivity.T",
        "noise = C_tt",
        (ROBOT + "test_stated_uncertainty_includes_the_identified_robot",),
        "the robot's remaining error counted twice (in the noise part and the robot part)",
    ),
    # --- chain: model choice, noise levels --------------------------------------------------------
    Mutant(
        "model-choice-se-sqrt-n",
        "calibration/chain/model_choice.py",
        "se_rmse = float(np.std(squares) / np.sqrt(s.n) / (2 * s.rmse_mm))",
        "se_rmse = float(np.std(squares) / (2 * s.rmse_mm))",
        (CHAIN + "test_cv_standard_error_covers_the_rmse_at_its_level",),
        "the CV RMSE's standard error without the √n of the mean (8x too large on 64 samples)",
    ),
    Mutant(
        "model-choice-se-delta",
        "calibration/chain/model_choice.py",
        "se_rmse = float(np.std(squares) / np.sqrt(s.n) / (2 * s.rmse_mm))",
        "se_rmse = float(np.std(squares) / np.sqrt(s.n) / s.rmse_mm)",
        (CHAIN + "test_cv_standard_error_covers_the_rmse_at_its_level",),
        "the delta method's factor 1/2 of the square root dropped",
    ),
    Mutant(
        "chain-noise-dof",
        "calibration/chain/noise.py",
        "dof = float(raw.size - h[rows[g]].sum())",
        "dof = float(raw.size)",
        (CHAIN + "test_noise_levels_are_unbiased_with_the_leverage_correction",),
        "the chain's noise levels without the leverages' degrees of freedom",
    ),
    Mutant(
        "chain-robot-term",
        "calibration/chain/fit.py",
        "covariance = noise_covariance + sensitivity @ robot_covariance @ sensitivity.T",
        "covariance = noise_covariance",
        (CHAIN + "test_stated_uncertainty_with_robot_error_is_calibrated",),
        "the chain's covariance without the stated robot accuracy's term",
    ),
    Mutant(
        "uncertainty-ellipsoid-dof",
        "calibration/chain/uncertainty.py",
        "return d2 <= chi2.ppf(level, 3)",
        "return d2 <= chi2.ppf(level, 2)",
        (CHAIN + "test_ellipsoids_hold_their_level",),
        "the 3D ellipsoid's quantile on 2 degrees of freedom",
    ),
    Mutant(
        "landing-robot-twice",
        "calibration/chain/uncertainty.py",
        "C = G @ fit.noise_covariance @ np.swapaxes(G, 1, 2)",
        "C = G @ fit.covariance @ np.swapaxes(G, 1, 2)",
        (LANDING,),
        "the predicted landing error counts the robot's error twice (in the parameters' and its own term)",
    ),
    Mutant(
        "landing-prior-only",
        "calibration/chain/uncertainty.py",
        "if fit.robot_posterior is None or fit.robot_mean is None:",
        "if True:",
        (LANDING,),
        "the predicted landing error from the stated accuracy alone, blind to what the residuals show of the robot",
    ),
    Mutant(
        "landing-encoder-noise",
        "calibration/chain/uncertainty.py",
        "C = C + fit.robot_accuracy.encoder_sd_rad**2 * L_q @ np.swapaxes(L_q, 1, 2)",
        "C = C + 0.0 * L_q @ np.swapaxes(L_q, 1, 2)",
        (LANDING,),
        "the predicted landing error without the joint readings' noise when aiming",
    ),
    Mutant(
        "session-sector-holds-none",
        "data/session.py",
        "    if outside.all():",
        "    if False:",
        ("tests/test_session_sector.py::test_a_sector_that_holds_none_of_the_tips_is_refused_naming_the_file_and_key",),
        "a session's imaging sector that holds none of its samples accepted",
    ),
    Mutant(
        "check-part-dof",
        "calibration/verify/check.py",
        "dof = len(r) - rank",
        "dof = len(r)",
        ("tests/test_verify.py::test_a_part_fit_recovers_the_change_that_made_the_residuals",),
        "the check's remaining chi-square without the part's fitted parameters",
    ),
    # --- result files read back: the one schema check, units from the data -----------------------
    Mutant(
        "schema-image-to-probe-skew",
        "data/json_schema.py",
        "if worst > MAX_SKEW_DEG:",
        "if worst > 90.0:",
        (HTP + "[template-slightly-sheared-image-to-probe]",),
        "an Image -> Probe matrix's columns not held at right angles (a shear within the spacing range)",
    ),
    Mutant(
        "schema-image-to-probe-spacing",
        "data/json_schema.py",
        "if not low <= length <= high:",
        "if not low <= length:",
        (HTP + "[template-sheared-image-to-probe]", HTP + "[export-sheared-image-to-probe]"),
        "an Image -> Probe column of 5 mm per pixel (one element set to 5) accepted",
    ),
    Mutant(
        "schema-image-to-probe-reach",
        "data/json_schema.py",
        "reach = float(np.max(np.abs(M[:3, 3]))) * 1e-3",
        "reach = 0.0",
        (HTP + "[template-image-to-probe-a-terametre-away]",),
        "an Image -> Probe translation of 1e12 mm accepted",
    ),
    Mutant(
        "schema-image-to-probe-handedness",
        "data/json_schema.py",
        "if np.linalg.det(U) <= 0.0:",
        "if np.linalg.det(U) <= -2.0:",
        (HTP + "[template-mirrored-image-to-probe]",),
        "a mirrored (left-handed) Image -> Probe accepted",
    ),
    Mutant(
        "schema-nwire-unchecked",
        "calibration/phantom/nwire_file.py",
        "raw = read_document(path, FORMAT, NWIRE_DOCUMENT)",
        "raw = read_document(path, FORMAT, Obj())",
        (HTP + "[template-sheared-image-to-probe]", HTP + "[export-image-to-probe-a-terametre-away]"),
        "an N-wire result read without its schema",
    ),
    Mutant(
        "schema-stepper-block-unchecked",
        "calibration/phantom/stepper_probe.py",
        'STEPPER_BLOCK(stepper, Where(path, "stepper"))',
        'Where(path, "stepper")',
        (HTP + "[template-phantom-a-terametre-away]", HTP + "[export-probe-axis-far-off-z]"),
        "a stepper result's registration and axes read without their schema",
    ),
    Mutant(
        "schema-pivot-tool-length",
        "calibration/phantom/pivot_file.py",
        "if not low <= length_m <= high:",
        "if False:",
        ("tests/test_result_formats.py::test_pivot_reader_refuses_a_tip_in_the_other_unit",),
        "a pivot result whose tip is in the other unit than its units say accepted",
    ),
    Mutant(
        "stepper-encoder-units",
        "data/formats/plus_files.py",
        "if low <= abs(ratio) <= high:",
        "if True:",
        (
            HST + "[probe-encoder-in-cm]",
            HST + "[rotation-encoder-in-radians]",
            "tests/test_stepper_calibration.py::test_an_encoder_in_another_unit_than_its_poses_is_refused",
        ),
        "a stepper encoder in cm (or radians) beside its poses in mm (degrees) accepted",
    ),
    Mutant(
        "stepper-image-without-axes",
        "data/formats/plus_stepper.py",
        "        return None",
        "        return STRAIGHT_AXES",
        (
            HTP + "[image-device-set-without-stepper-calibration]",
            "tests/test_stepper_twin.py::test_poses_as_recorded_are_asked_for_and_said",
        ),
        "a device set without StepperCalibration taken as straight axes, silently",
    ),
    Mutant(
        "tracker-degrees-from-data",
        "data/formats/tracker_table.py",
        "if largest.max() > np.pi or joint_turn < MIN_JOINT_TURN_RAD:",
        "if True:",
        (
            TRACK + "test_radians_stated_as_degrees_are_refused_from_the_data",
            "tests/test_hostile_tracker.py::test_refused_in_one_line_with_nothing_written[radians-stated-as-degrees]",
        ),
        "tracker orientation in radians stated as degrees accepted",
    ),
    # --- hostile inputs and outputs: each check's break-on-purpose --------------------------------------
    Mutant(
        "bag-message-count-unchecked",
        "data/formats/bag_records.py",
        "if isinstance(count, bool) or not isinstance(count, int) or count < 0:",
        "if False:",
        ("tests/test_hostile_data.py::test_data_refusals[fk-ros2-bag-message-count-negative]",),
        "a ROS 2 bag's metadata.yaml message_count taken unchecked (inf: a TypeError traceback)",
    ),
    Mutant(
        "stepper-template-depth-unbounded",
        "cli/stepper/template.py",
        'DEPTH_MM = finite_float(low=0.0, high=300.0, unit="mm")',
        'DEPTH_MM = finite_float(unit="mm")',
        ("tests/test_hostile_parameters.py::test_parameter_refusals[stepper--depth-huge]",),
        "an insertion depth of 1e6 mm accepted by stepper template",
    ),
    Mutant(
        "stepper-template-rotation-unbounded",
        "cli/stepper/template.py",
        'ROTATION_DEG = finite_float(low=-360.0, high=360.0, unit="deg")',
        'ROTATION_DEG = finite_float(unit="deg")',
        ("tests/test_hostile_parameters.py::test_parameter_refusals[stepper--probe-rotation-huge]",),
        "a probe rotation of 1e308 deg reaches the trigonometry (a math domain error traceback)",
    ),
    Mutant(
        "nwire-segment-poses-fix-unsaid",
        "imaging/nwire_segmentation.py",
        '+ (f"; {fix}" if fix else ""),',
        ",",
        ("tests/test_hostile_nwire_segment.py::test_refused[tracker-recording-without-poses]",),
        "a recording without the tracker's transforms refused without naming --images-only",
    ),
    Mutant(
        "output-lock-pid-on-full-disk",
        "io.py",
        "with contextlib.suppress(OSError):  # a full disk: the lock holds without its holder's pid",
        "if True:",
        ("tests/test_files.py::test_a_disk_too_full_for_the_lock_holders_pid_still_locks_and_leaves_nothing",),
        "a full disk fails the lock's pid write: the lock file and the output's folder are left behind",
    ),
    Mutant(
        "output-new-folder-replaces-a-made-one",
        "io.py",
        "if os.path.lexists(folder.destination):",
        "if False:",
        ("tests/test_files.py::test_a_folder_made_at_the_destination_while_the_command_ran_is_kept",),
        "a folder made while the command ran is not named (or, empty, replaced by the staged one)",
    ),
    Mutant(
        "output-stale-staging-folder-kept",
        "io.py",
        "if stale.is_dir() and not stale.is_symlink():",
        "if False:",
        ("tests/test_hostile_outputs.py::test_after_kill_9_during_calibrate_report_no_visible_folder_is_left",),
        "the staging folder a killed writer left is never removed",
    ),
    Mutant(
        "csv-blanks-around-fields-kept",
        "data/formats/csv_log.py",
        "records.append([field.strip(BLANKS) for field in fields])",
        "records.append(fields)",
        ("tests/test_number_text.py::test_a_table_with_blanks_around_its_fields_reads_as_numpy_reads_it",),
        'a table written with ", " separators (numpy.savetxt, spreadsheets) refused',
    ),
    Mutant(
        "csv-log-cr-only-unsaid",
        "data/formats/csv_log.py",
        'if b"\\r" in first.rstrip(b"\\r\\n"):',
        "if False:",
        ("tests/test_number_text.py::test_a_log_with_old_mac_line_ends_is_refused_in_one_line_naming_them",),
        "a joint log with CR-only line ends gets the csv module's words, not a refusal naming them",
    ),
    Mutant(
        "joint-table-cr-only-misread",
        "data/formats/joint_table.py",
        '.split("\\r")[0].strip()',
        ".strip()",
        ("tests/test_number_text.py::test_a_joint_table_without_header_reads_the_same_from_other_writers",),
        "a headerless joint table with CR-only line ends taken for a table with a header",
    ),
    Mutant(
        "urdfdom-errors-ignored",
        "model/robot.py",
        "if errors:  # urdfdom's own words; an element it could not read is dropped, not a model to use",
        "if False:",
        ("tests/test_hostile_model.py::test_urdfdom_errors_are_one_line_naming_the_file_not_its_own_printout",),
        "a URDF whose inertial urdfdom could not read loads without it; its errors not in the refusal",
    ),
    Mutant(
        "session-copied-row-accepted",
        "data/session.py",
        "    if repeats.size:",
        "    if False:",
        ("tests/test_hostile_data.py::test_data_refusals[calibrate-session-sample-copied-under-a-new-name]",),
        "a sample copied under a new name counts twice in the fit",
    ),
    Mutant(
        "number-check-backtracks-per-field",
        "validate.py",
        '{NON_FINITE_TEXT})\\n)*+")',
        '{NON_FINITE_TEXT})\\n)*")',
        ("tests/test_number_text.py::test_checking_many_fields_at_once_holds_no_memory_per_field",),
        "the one-pass number check keeps ~800 bytes per field (pivot on a 63 MB pose list: 3.3 GB)",
    ),
    Mutant(
        "pose-list-read-whole",
        "data/pose_list.py",
        "in table_blocks(path, COLUMNS):",
        "in table_blocks(path, COLUMNS, None):",
        ("tests/test_pivot.py::test_a_long_pose_list_is_read_in_bounded_memory",),
        "a pose list held whole as Python strings (13 times the file)",
    ),
    Mutant(
        "output-error-python-words",
        "errors.py",
        "super().__init__(self.spelled(self.PYTHON_FORCE))",
        'super().__init__(self.spelled("--force"))',
        ("tests/test_files.py::test_never_replaces_without_force",),
        "an output refused to a Python caller advises the command line's --force",
    ),
    Mutant(
        "output-error-cli-words",
        "cli/main.py",
        "print(f\"brachycal: error: {exc.spelled('--force')}\", file=sys.stderr)",
        'print(f"brachycal: error: {exc}", file=sys.stderr)',
        ("tests/test_cli.py::test_fk_refuses_to_overwrite_without_force",),
        "an output refused on the command line advises Python's force=True",
    ),
    Mutant(
        "summary-table-i-figure",
        "calibration/sequential/method.py",
        'f"MAE {tool.validation.mae_mm:.2f} mm over {tool.validation.n} trials"',
        'f"MAE {tool.validation.rmse_mm:.2f} mm over {tool.validation.n} trials"',
        (
            "tests/test_summaries.py::test_a_sequential_result_prints_its_tools_their_table_i_and_each_methods_leave_one_out",
        ),
        "print(result) shows Table I's RMSE as its MAE",
    ),
    Mutant(
        "summary-probe-tip",
        "calibration/result.py",
        'f"  T_EL_Ptip  probe_tip at {point_mm(self.T_EL_Ptip)} in the probe flange",',
        'f"  T_EL_Ptip  probe_tip at {point_mm(self.T_ER_Ntip)} in the probe flange",',
        ("tests/test_summaries.py::test_a_calibration_prints_its_method_transforms_spacing_and_source",),
        "print(calibration) shows the needle tip as the probe's",
    ),
    Mutant(
        "tracker-spec-key-called-column",
        "data/formats/tracker_table.py",
        'raise InputError("unknown key", file=source, key=unknown[0])',
        'raise InputError("unknown key", file=source, column=unknown[0])',
        ("tests/test_tracker_identification.py::test_column_spec_refusals_name_the_key",),
        "a column spec's TOML key named a column in its refusal",
    ),
    Mutant(
        "orientation-ignored",
        "data/formats/metaimage.py",
        'pixels=to_mf(pixels.astype(dtype.newbyteorder("="), copy=False), orientation),',
        'pixels=pixels.astype(dtype.newbyteorder("="), copy=False),',
        (
            ORIENT + "test_every_plus_orientation_reads_to_the_mf_frames",
            ORIENT + "test_stepper_calibrate_is_the_same_in_every_orientation",
        ),
        "a sequence's frames kept as stored, whatever its UltrasoundImageOrientation (not PLUS's MF)",
    ),
    Mutant(
        "orientation-wrong-axis",
        "data/formats/metaimage.py",
        "pixels = pixels[:, ::-1, :]",
        "pixels = pixels[:, :, ::-1]",
        (ORIENT + "test_every_plus_orientation_reads_to_the_mf_frames",),
        "an N (near) orientation turned to MF by reversing the columns instead of the rows",
    ),
    Mutant(
        "pattern-geometry-unchecked",
        "imaging/nwire_patterns.py",
        "if not geometry.patterns or phantom_misfit(points, geometry, params) <= 1.0:",
        "if True:",
        (
            "tests/test_nwire_pattern_geometry.py::test_a_bright_dot_where_the_diagonal_is_not_is_not_taken_for_it",
            "tests/test_nwire_pattern_geometry.py::test_a_frame_whose_only_pattern_fits_no_plane_is_not_segmented",
        ),
        "an N pattern taken for the frame's though no one plane through the phantom fits it",
    ),
    Mutant(
        "check-build-takes-calibration-marks",
        "data/session_build.py",
        'if mark.kind != "touch" or mark.tool not in CHECK_TOOLS:',
        "if False:",
        ("tests/test_hostile_session.py::test_check_build_refusals[session-recording-given-to-a-check-build]",),
        "a calibration recording built as a check: top-model touches and axes moves taken as check touches",
    ),
    Mutant(
        "check-build-without-its-touch",
        "data/session_build.py",
        'if (tool, "rtip1") not in touch_q:',
        "if False:",
        ("tests/test_hostile_session.py::test_check_build_refusals[check-without-its-touch]",),
        "a check built without the touch it planned: a probe remount then reads as an image change",
    ),
    Mutant(
        "check-build-of-two-frames",
        "data/session_build.py",
        "if check is not None and len(names) < MIN_CHECK_SAMPLES:",
        "if False:",
        ("tests/test_hostile_session.py::test_check_build_refusals[check-of-two-frames]",),
        "a check session of fewer frames than any check reads, written for verify to refuse later",
    ),
    Mutant(
        "session-build-takes-a-check-recording",
        "data/session_build.py",
        'if not any(tool == "top_model" for tool, _ in touch_q) and not any(axes.values()):',
        "if False:",
        ("tests/test_hostile_session.py::test_check_build_refusals[check-recording-given-to-a-session-build]",),
        "a check recording given to a session build is refused without saying it is a check's (--check)",
    ),
    # --- the command line's vocabulary: verdict, progress, next: lines, common options ---------------
    Mutant(
        "verdict-no-se",
        "calibration/robot/identification.py",
        "use = len(gains) > 1 and gain > VERDICT_STANDARD_ERRORS * se",
        "use = len(gains) > 1 and gain > 0",
        ("tests/test_identification_verdict.py::test_a_gain_within_chance_says_keep_the_urdf",),
        "the identified robot advised for any held-out gain, chance included",
    ),
    Mutant(
        "verdict-pooled",
        "calibration/robot/identification.py",
        'se = float(gains.std(ddof=1) / np.sqrt(len(gains))) if len(gains) > 1 else float("inf")',
        'se = float(gains.std(ddof=1) / len(gains)) if len(gains) > 1 else float("inf")',
        ("tests/test_identification_verdict.py::test_the_verdict_reads_the_folds_not_the_pooled_samples",),
        "the gain's standard error too small (over the folds' count, not its root): one lucky fold decides",
    ),
    Mutant(
        "progress-no-folds",
        "calibration/session/chain_report.py",
        "            if started[0] <= folds:",
        "            if started[0] < 0:",
        ("tests/test_cli_progress.py::test_the_identification_names_each_stage_with_its_counts",),
        "the held-out folds run without a progress line",
    ),
    Mutant(
        "next-quiet-ignored",
        "cli/common.py",
        "    if quiet or not commands:",
        "    if not commands:",
        ("tests/test_cli_vocabulary.py::test_calibrate_names_the_next_commands_and_quiet_leaves_them_out",),
        "--quiet does not leave out the next: line",
    ),
    # --- the HTML report holds what the terminal shows, captioned and judged ------------------------
    Mutant(
        "report-uncertainty-column-left-out",
        "reporting/html_report.py",
        "uncertainty_columns=UNCERTAINTY_COLUMNS,",
        "uncertainty_columns=UNCERTAINTY_COLUMNS[:-1],",
        (HTML + "test_every_line_the_terminal_prints_is_a_line_of_the_report",),
        "the report's predicted-uncertainty table heads one column fewer than the terminal prints",
    ),
    Mutant(
        "report-best-sequential-for-chain",
        "reporting/html_report.py",
        'method, rmse = "chain", chain.loocv.rmse_mm',
        "method, rmse = sequential_best(result), None",
        (HTML + "test_the_report_names_the_method_the_results_commands_use_and_why",),
        "the report names the lowest-RMSE registration as the best where the result's commands use the chain",
    ),
    Mutant(
        "report-figures-uncaptioned",
        "reporting/html_report.py",
        'figures=[_figure(f, captions.get((staged_destination(f) or f).name, "")) for f in figures],',
        "figures=[_figure(f) for f in figures],",
        (HTML + "test_every_figure_has_a_caption_with_its_units",),
        "figures embedded without their captions",
    ),
    Mutant(
        "report-judged-always-good",
        "reporting/judgement.py",
        'return Judged(figure, value, good_if, "good" if inside else "beyond: brachycal warns", source, not inside)',
        'return Judged(figure, value, good_if, "good", source, False)',
        (HTML + "test_a_figure_beyond_its_threshold_is_judged_bad",),
        "every figure judged good whatever its value",
    ),
    Mutant(
        "report-spacing-change-not-judged",
        "reporting/judgement.py",
        "change <= WARN_SPACING_CHANGE * 100,",
        "True,",
        (HTML + "test_a_figure_beyond_its_threshold_is_judged_bad",),
        "a fitted pixel spacing far off the session's judged good",
    ),
    Mutant(
        "report-landing-judged-over-whole-image",
        "reporting/judgement.py",
        'fov, where = inside, "the imaging sector"',
        'where = "the imaging sector"',
        (HTML + "test_a_figure_beyond_its_threshold_is_judged_bad",),
        "the landing error judged over the whole image while the page says over the imaging sector",
    ),
)


def by_name(names: list[str]) -> list[Mutant]:
    """The mutants named (all when empty); an unknown name exits with the list of known ones."""
    known = {m.name: m for m in MUTANTS}
    unknown = [n for n in names if n not in known]
    if unknown:
        sys.exit(f"unknown mutant(s) {', '.join(unknown)}; known: {', '.join(known)}")
    return [known[n] for n in names] if names else list(MUTANTS)


def run_tests(tests: tuple[str, ...] | list[str], mutant: Mutant | None) -> tuple[int, float, str]:
    """``(pytest exit code, seconds, last output line)`` of ``tests`` against a copy of ``src/`` with
    ``mutant`` applied (none: the unmutated copy)."""
    with tempfile.TemporaryDirectory(prefix="brachycal-mutant-") as tmp:
        src = Path(tmp) / "src"
        shutil.copytree(ROOT / "src", src, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        for data in BUNDLED:  # read beside src/ (brachycal.io.bundled)
            (Path(tmp) / data).symlink_to(ROOT / data, target_is_directory=True)
        if mutant is not None:
            path = src / "brachycal" / mutant.file
            text = path.read_text()
            if text.count(mutant.original) != 1:
                return 3, 0.0, f"snippet occurs {text.count(mutant.original)} times in {mutant.file}"
            path.write_text(text.replace(mutant.original, mutant.replacement))
        env = dict(os.environ, PYTHONPATH=str(src), PYTHONDONTWRITEBYTECODE="1", COLUMNS="250")
        where = subprocess.run(
            [sys.executable, "-c", "import brachycal; print(brachycal.__file__)"],
            env=env,
            capture_output=True,
            text=True,
        ).stdout.strip()
        if not where.startswith(str(src)):  # an installed brachycal would shadow the copy: nothing tested
            return 4, 0.0, f"brachycal imported from {where or '?'}, not from the copy {src}"
        command = [sys.executable, "-m", "pytest", *tests, "-x", "-q", "-rfE", "-p", "no:cacheprovider", "--no-header"]
        start = time.perf_counter()
        try:
            done = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True, timeout=TIMEOUT_S)
        except subprocess.TimeoutExpired:
            return 1, time.perf_counter() - start, f"caught by the timeout ({TIMEOUT_S:g} s), not by a failure"
        lines = [line for line in done.stdout.splitlines() if line.startswith(("FAILED", "ERROR"))]
        lines = lines or [line for line in done.stdout.splitlines() if line.strip()][-1:]
        return done.returncode, time.perf_counter() - start, "; ".join(lines) or done.stderr.strip()[-200:]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("names", nargs="*", help="mutants to run (default: all)")
    parser.add_argument("--jobs", type=int, default=1, help="mutants run at once (default 1)")
    parser.add_argument("--list", action="store_true", help="print the table and exit")
    parser.add_argument("--details", action="store_true", help="also print the failure that caught each mutant")
    args = parser.parse_args(argv)
    mutants = by_name(args.names)
    if args.list:
        for m in mutants:
            print(f"{m.name:36s} {m.file}: {m.why}\n    - {m.original}\n    + {m.replacement}")
            print("".join(f"    test {t}\n" for t in m.tests), end="")
        return 0
    start = time.perf_counter()
    tests = sorted({t for m in mutants for t in m.tests})
    code, seconds, last = run_tests(tests, None)
    print(f"baseline: {len(tests)} tests on the unmutated source: {'pass' if code == 0 else 'FAIL'} ({seconds:.0f} s)")
    if code != 0:
        print(f"  {last}")
        return 2
    with ThreadPoolExecutor(max(1, args.jobs)) as pool:
        outcomes = list(pool.map(lambda m: run_tests(m.tests, m), mutants))
    failed = 0
    for m, (code, seconds, last) in zip(mutants, outcomes, strict=True):
        verdict = {0: "SURVIVED", 1: "caught"}.get(code, f"ERROR (pytest exit {code})")
        failed += code != 1
        print(f"{verdict:10s} {m.name:36s} {m.file:38s} {seconds:5.0f} s  {'; '.join(m.tests)}")
        if code != 1 or args.details:
            print(f"           {last}")
    caught = sum(code == 1 for code, _, _ in outcomes)
    print(f"{caught} of {len(mutants)} mutants caught in {time.perf_counter() - start:.0f} s")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
