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
