"""Whole-chain calibration: exactness, robustness, model choice, calibrated uncertainty, conditioning, designs.

The coverage figures over many sessions (docs/validation.md's) come from ``benchmarks/chain_checks.py``;
the tests here are the smaller, two-sided checks that run in CI.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from bands import assert_calibrated, assert_unbiased_variance, coverage_band
from scipy.optimize import approx_fprime
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from brachycal.calibration import calibrate
from brachycal.calibration.chain import (
    DEFAULT_ROBOT_ACCURACY,
    MODELS,
    ROTATION_SD_LIMIT,
    ChainData,
    ParameterLayout,
    RobotAccuracy,
    chain_jacobian,
    chain_residuals,
    fit_chain,
    identifiable_joint_offsets,
    noise_levels,
    robot_jacobian,
    select_model,
)
from brachycal.calibration.chain.model_choice import ModelChoice
from brachycal.calibration.chain.uncertainty import (
    bootstrap,
    inside_ellipsoid,
    interval,
    landing_covariance,
    landing_jacobian,
    landing_robot_jacobians,
)
from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.session.chain_report import WARN_LANDING_RMS_MM, calibrate_chain
from brachycal.cli.main import main
from brachycal.errors import DegenerateDataError, InputError
from brachycal.se3 import make_transform
from brachycal.simulation.twin import TwinConfig, simulate
from brachycal.studies.design import grid_offsets, optimal_offsets
from brachycal.studies.targeting import targeting_error


@pytest.fixture(scope="module")
def stretched(robot):
    twin = simulate(robot, TwinConfig(seed=0))
    return twin, calibrate(twin.session, robot)


def test_noise_free_twin_every_image_model_is_exact(robot):
    twin = simulate(robot, TwinConfig(seed=1).without_noise())
    initial = calibrate(twin.session, robot, ("scaled_uv",))
    for model in MODELS:
        fit = fit_chain(twin.session, robot, initial, model)
        assert np.abs(fit.T_ER_Ntip - twin.truth.T_ER_Ntip).max() < 1e-9, model
        assert np.abs(fit.T_EL_I() - twin.truth.T_EL_Ptip @ twin.truth.T_Ptip_I).max() < 1e-9
        assert np.abs(fit.image.spacing_m - twin.truth.spacing_m).max() < 1e-15
        assert not fit.outliers.any()
        # Exact data have no noise to measure: said so, not printed as a noise level.
        assert fit.noise["image"].source == fit.noise["touch"].source == "below resolution"


def test_analytic_jacobian_matches_central_differences(robot, stretched):
    twin, sequential = stretched
    data = ChainData.of(twin.session, robot)
    rng = np.random.default_rng(0)
    sigma = {"touch": 1e-4, "axes": 2e-4, "image": 3e-4}
    use = rng.random(len(twin.session.uv_px)) > 0.2
    for model in MODELS:
        layout = ParameterLayout(model)
        x, base = layout.start(sequential, data.spacing_m)
        for name in ("rot_ER_Ntip", "rot_EL_Ptip", "rot_Ptip_I"):  # away from the start: J_l(ω) ≠ I matters
            x[layout.blocks()[name]] += rng.normal(scale=0.05, size=3)
        step = 1e-6

        def r(x: np.ndarray, layout=layout, base=base) -> np.ndarray:
            return chain_residuals(x, layout, data, base, sigma, use)

        numeric = np.column_stack([(r(x + step * e) - r(x - step * e)) / (2 * step) for e in np.eye(len(x))])
        analytic = chain_jacobian(x, layout, data, base, sigma, use)
        # Central differences are exact to ~1e-10 of the largest entry here (step² × curvature,
        # rounding / step); a wrong term would be off by its own size.
        assert np.abs(analytic - numeric).max() < 1e-8 * np.abs(numeric).max(), model


def test_chain_beats_the_papers_rigid_method_fourfold_under_a_4_percent_stretch(robot, stretched):
    twin, sequential = stretched
    choice = select_model(twin.session, robot, sequential)
    assert choice.model in ("scaled_uv", "sound_speed")
    fit = fit_chain(twin.session, robot, sequential, choice.model)
    assert abs(fit.sound_speed_m_s - 1482) < 15  # the speed of sound is measured, not assumed
    chain = targeting_error(twin, fit.calibration(), 30).stats
    paper = targeting_error(twin, sequential.calibration("kabsch"), 30).stats
    assert chain.mae_mm <= paper.mae_mm / 4


@pytest.mark.parametrize("seed", [2, 5, 9])
@pytest.mark.filterwarnings("ignore::brachycal.errors.ConditioningWarning")  # the sequential start, on the mistakes
def test_gross_outliers_are_flagged_left_out_and_barely_matter(robot, seed):
    clean = simulate(robot, TwinConfig(seed=seed))
    dirty = simulate(robot, replace(TwinConfig(seed=seed), outliers=True))
    assert dirty.outlier.sum() >= 3
    hits = []
    for twin in (clean, dirty):
        initial = calibrate(twin.session, robot, ("scaled_uv",))
        fit = fit_chain(twin.session, robot, initial, "sound_speed")
        hits.append(targeting_error(twin, fit.calibration(), 30).stats.mae_mm)
        assert np.array_equal(fit.outliers, twin.outlier)
    # Left out, not down-weighted: the fit equals the fit without those samples (to its solver's tolerance).
    without = fit_chain(dirty.session, robot, initial, "sound_speed", samples=~dirty.outlier)
    assert np.abs(without.x - fit.x).max() < 1e-9
    # Over seeds 0-19 the ratio runs 0.89-1.17, median 1.03 (benchmarks/chain_checks.py, section 2):
    # 1.2 is docs/validation.md's bound, which a fit that kept the mistakes broke on 3 of 10 seeds (up to 1.86).
    # Here (sound-speed model) seeds 2, 5, 9 run 1.16, 1.15, 0.89: 2 and 5 among the highest, where the bound is tight.
    assert hits[1] <= 1.2 * hits[0]


def test_without_a_stretch_the_simplest_model_is_chosen(robot):
    twin = simulate(robot, replace(TwinConfig(seed=3), sound_speed=False))
    choice = select_model(twin.session, robot, calibrate(twin.session, robot, ("scaled_uv",)))
    assert choice.model == "rigid"
    evidence = choice.evidence()
    assert (
        evidence["rigid"]["cv_rmse_mm"]
        <= min(e["cv_rmse_mm"] for e in evidence.values()) + evidence["rigid"]["se_mm"] * 2
    )


def test_cv_standard_error_covers_the_rmse_at_its_level():
    # The evidence's standard error of an RMSE over n errors (delta method on the mean of e²) against
    # the RMSE's spread over many sets: 3D errors of σ per axis, true RMSE √3 σ.
    rng = np.random.default_rng(23)
    sigma_mm, n, draws = 0.4, 64, 400
    z2 = []
    for _ in range(draws):
        errors = ErrorStats(np.linalg.norm(rng.normal(scale=sigma_mm * 1e-3, size=(n, 3)), axis=1))
        evidence = ModelChoice("rigid", {"rigid": errors}, "", n).evidence()["rigid"]
        z2.append(((evidence["cv_rmse_mm"] - np.sqrt(3.0) * sigma_mm) / evidence["se_mm"]) ** 2)
    assert_calibrated(z2, 1)


def test_noise_levels_are_unbiased_with_the_leverage_correction():
    # A linear weighted problem with three groups of 16 rows and 12 parameters: each group's residual
    # sum of squares has expectation σ_g² (n_g − Σ_g h_ii), so σ̂_g² is unbiased. (Its spread is at most
    # that of χ² with n_g − Σ_g h_ii degrees of freedom: the band is conservative.)
    rng = np.random.default_rng(24)
    J = rng.normal(size=(48, 12))
    rows = {"touch": slice(0, 16), "axes": slice(16, 32), "image": slice(32, 48)}
    sigma = {"touch": 5e-5, "axes": 1e-4, "image": 2e-4}
    h = np.einsum("ij,jk,ik->i", J, np.linalg.inv(J.T @ J), J)
    draws, ratios = 300, {g: [] for g in rows}
    for _ in range(draws):
        noise = rng.normal(size=48)
        residual = noise - J @ np.linalg.lstsq(J, noise, rcond=None)[0]
        levels = noise_levels(residual, J, rows, sigma, robust=False)
        for g, part in rows.items():
            assert levels[g].dof == pytest.approx(16 - h[part].sum(), rel=1e-9)
            ratios[g].append((levels[g].sd_m / sigma[g]) ** 2)
    for g, part in rows.items():
        assert_unbiased_variance(ratios[g], 16 - h[part].sum())


def test_ellipsoids_hold_their_level():
    # Errors drawn from their covariance (3D, anisotropic, correlated) fall inside the 95 % ellipsoid
    # 95 % of the time (binomial band of the draws).
    rng = np.random.default_rng(26)
    draws = 2000
    L = np.tril(rng.normal(size=(draws, 3, 3))) + 2 * np.eye(3)
    C = L @ np.swapaxes(L, 1, 2) * 1e-8
    errors = np.einsum("nij,nj->ni", L, rng.normal(size=(draws, 3))) * 1e-4
    inside = inside_ellipsoid(errors, C)
    low, high = coverage_band(draws, 0.95)
    assert low <= inside.mean() <= high


def _parameter_errors(fit, truth) -> tuple[np.ndarray, np.ndarray]:
    """Error of every quantity the data determine with their own noise level, and its covariance.

    The needle and probe tips, the reference tips, the depth scale and the image frame on the left
    flange (rotation vector and origin). Left out: the tool rotations alone, which rest on the
    axes moves' assumed noise level (the touches', deliberately conservative).
    """
    T_true = truth.T_EL_Ptip @ truth.T_Ptip_I
    direct = [("p_ER_Ntip", truth.T_ER_Ntip[:3, 3]), ("p_EL_Ptip", truth.T_EL_Ptip[:3, 3])]
    direct += [("p_R_Rtip1", truth.p_R_Rtip1), ("p_R_Rtip2", truth.p_R_Rtip2)]
    direct += [("scale", np.array([truth.spacing_m[1] / truth.nominal_spacing_m[1]]))]
    rows, errors = [], []
    for name, true in direct:
        k = fit.block(name)
        rows.append(np.eye(len(fit.x))[k])
        errors.append(fit.x[k] - true)

    def image_frame(x: np.ndarray) -> np.ndarray:
        T = fit.T_EL_I(x)
        return np.r_[Rotation.from_matrix(T[:3, :3] @ T_true[:3, :3].T).as_rotvec(), T[:3, 3] - T_true[:3, 3]]

    rows.append(approx_fprime(fit.x, image_frame, 1e-8))
    errors.append(image_frame(fit.x))
    G = np.vstack(rows)
    return np.concatenate(errors), G @ fit.covariance @ G.T


EXACT_ROBOT = RobotAccuracy(0.0, 0.0, 0.0, "exact")


@pytest.mark.slow
def test_stated_uncertainty_is_calibrated_on_both_sides(robot):
    """Standardised errors over 8 sessions of a twin whose robot is exactly its model, stated so
    (robot accuracy 0: the covariance is the session's noise alone; the default twin, with robot
    error stated at its level, is :func:`test_stated_uncertainty_with_robot_error_is_calibrated`).

    Under the model, each session's 19 parameter errors (tips, reference tips, depth scale, image
    frame) give d² ~ χ²₁₉ and each session's landing error at one target d² ~ χ²₃, independent across
    sessions: Σd² ~ χ²₁₅₂ and χ²₂₄. The two-sided 99 % bounds (Σd²/152 in 0.73..1.31) fail both a
    covariance 1.3× too wide in SD (as the robust-loss covariance was for the speed of sound:
    expected 0.59) and 1.3× too narrow (1.69), each with probability > 0.95; a calibrated one
    fails with probability 0.01.
    """
    runs, parameter_d2, landing_d2, parameter_dof = 8, 0.0, 0.0, 0
    for seed in range(10, 10 + runs):
        twin = simulate(robot, replace(TwinConfig(seed=seed), kinematic_error=False))
        initial = calibrate(twin.session, robot, ("scaled_uv",))
        fit = fit_chain(twin.session, robot, initial, "sound_speed", robot_accuracy=EXACT_ROBOT)
        error, C = _parameter_errors(fit, twin.truth)
        parameter_d2 += error @ np.linalg.solve(C, error)
        parameter_dof += len(error)
        exact_reading = replace(twin, config=replace(twin.config, encoder_noise=False))  # the calibration's part
        hit = targeting_error(exact_reading, fit.calibration(), 1)
        C_land = landing_covariance(fit, robot, twin.session.spacing_m, hit.q_read, hit.uv_px)[0]
        e = hit.landed_m[0] - hit.targets_m[0]
        landing_d2 += e @ np.linalg.solve(C_land, e)
    assert parameter_dof == 19 * runs
    low, high = chi2.ppf([0.005, 0.995], parameter_dof)
    assert low <= parameter_d2 <= high, (parameter_d2 / parameter_dof, low / parameter_dof, high / parameter_dof)
    low, high = chi2.ppf([0.005, 0.995], 3 * runs)
    assert low <= landing_d2 <= high, landing_d2 / (3 * runs)


@pytest.mark.slow
def test_stated_uncertainty_with_robot_error_is_calibrated(robot):
    """The default twin (its physical robot off its URDF by 0.03 mm / 0.003° per joint, the default
    stated accuracy): the covariance with the robot term must cover the tips, reference tips,
    depth scale and image frame, and the landing error when aiming with noisy joint readings.

    The same χ² argument as above (Σd² ~ χ²₁₅₂ and χ²₂₄ over 8 sessions, two-sided 99 % bounds).
    Without the robot term the tips' errors are 1.3-2× their noise-only SD
    (``benchmarks/chain_checks.py``): the bound fails that covariance, and one stated 2× too small.
    """
    runs, parameter_d2, landing_d2, parameter_dof, noise_only_d2 = 8, 0.0, 0.0, 0, 0.0
    for seed in range(20, 20 + runs):
        twin = simulate(robot, TwinConfig(seed=seed))
        initial = calibrate(twin.session, robot, ("scaled_uv",))
        fit = fit_chain(twin.session, robot, initial, "sound_speed")
        error, C = _parameter_errors(fit, twin.truth)
        parameter_d2 += error @ np.linalg.solve(C, error)
        noise_only = fit_chain(twin.session, robot, initial, "sound_speed", robot_accuracy=None)  # image noise only
        noise_only_d2 += error @ np.linalg.solve(_parameter_errors(noise_only, twin.truth)[1], error)
        parameter_dof += len(error)
        hit = targeting_error(twin, fit.calibration(), 1)  # encoder noise when aiming
        C_land = landing_covariance(fit, robot, twin.session.spacing_m, hit.q_read, hit.uv_px)[0]
        e = hit.landed_m[0] - hit.targets_m[0]
        landing_d2 += e @ np.linalg.solve(C_land, e)
    low, high = chi2.ppf([0.005, 0.995], parameter_dof)
    assert low <= parameter_d2 <= high, (parameter_d2 / parameter_dof, low / parameter_dof, high / parameter_dof)
    assert noise_only_d2 > high, noise_only_d2 / parameter_dof  # the robot term is what makes it right
    low, high = chi2.ppf([0.005, 0.995], 3 * runs)
    assert low <= landing_d2 <= high, landing_d2 / (3 * runs)


def test_robot_jacobian_matches_a_perturbed_urdf(robot, stretched):
    """``J_c`` (flange poses moved by each joint origin's twist) against the residuals of robots
    whose URDF origins are rewritten (:meth:`Robot.with_joint_origins`, the twin's way): torso,
    both arms, translations and rotations. Measured agreement ~1e-9 relative; 1e-6 leaves room
    for the URDF text's rounding while failing any wrong frame, sign or ancestry (order-1 errors).
    """
    twin, sequential = stretched
    fit = fit_chain(twin.session, robot, sequential, "sound_speed")
    J_c = robot_jacobian(twin.session, robot, fit)
    layout, keep, step = ParameterLayout(fit.model), ~fit.outliers, 1e-6

    def residuals(moved_robot) -> np.ndarray:
        return chain_residuals(fit.x, layout, ChainData.of(twin.session, moved_robot), fit.base, fit.sigma_m, keep)

    for j, d in [(0, 0), (0, 4), (3, 1), (5, 5), (10, 2), (12, 3), (14, 5)]:
        name, sides = robot.joint_names[j], []
        for sign in (1, -1):
            xi = np.zeros(6)
            xi[d] = sign * step
            motion = make_transform(Rotation.from_rotvec(xi[3:]).as_matrix(), xi[:3])
            sides.append(residuals(robot.with_joint_origins({name: robot.joint_origin(name) @ motion})))
        independent = (sides[0] - sides[1]) / (2 * step)
        column = J_c[:, 6 * j + d]
        assert np.linalg.norm(column - independent) < 1e-6 * np.linalg.norm(column), (name, d)
    # The landing's robot Jacobian (analytic) is the image residual's: the same numbers as J_c's image rows.
    L_c, _ = landing_robot_jacobians(fit, robot, twin.session.spacing_m, twin.session.samples_q, twin.session.uv_px)
    image_rows = J_c[-3 * int(keep.sum()) :].reshape(-1, 3, J_c.shape[1]) * fit.sigma_m["image"]
    assert np.abs(L_c[keep] - image_rows).max() < 1e-6 * np.abs(image_rows).max()


def test_robot_term_vanishes_with_zero_accuracy_and_scales_with_its_square(robot, stretched):
    twin, sequential = stretched
    q, uv = twin.session.samples_q[:5], twin.session.uv_px[:5]
    exact = fit_chain(twin.session, robot, sequential, "sound_speed", robot_accuracy=EXACT_ROBOT)
    assert np.array_equal(exact.covariance, exact.noise_covariance)
    G = landing_jacobian(exact, robot, twin.session.spacing_m, q, uv)
    no_robot = landing_covariance(exact, robot, twin.session.spacing_m, q, uv, encoder_noise=False)
    assert np.allclose(no_robot, G @ exact.noise_covariance @ np.swapaxes(G, 1, 2), rtol=1e-12, atol=0)
    default = fit_chain(twin.session, robot, sequential, "sound_speed")
    double = fit_chain(
        twin.session,
        robot,
        sequential,
        "sound_speed",
        robot_accuracy=RobotAccuracy(
            2 * DEFAULT_ROBOT_ACCURACY.translation_sd_m,
            2 * DEFAULT_ROBOT_ACCURACY.rotation_sd_rad,
            2 * DEFAULT_ROBOT_ACCURACY.encoder_sd_rad,
        ),
    )
    plain = fit_chain(twin.session, robot, sequential, "sound_speed", robot_accuracy=None)
    assert np.allclose(exact.covariance, plain.covariance, rtol=0, atol=1e-9 * np.abs(plain.covariance).max())
    assert np.array_equal(default.x, exact.x)  # the stated accuracy changes the intervals, never the estimate
    # The robot's error seen in the residuals (the touches' spread) is not counted twice: each
    # group keeps the share of its residual variance the stated accuracy does not explain.
    assert all(0.0 <= double.noise_share[g] <= default.noise_share[g] <= 1.0 for g in default.noise_share)
    assert default.noise_share["touch"] < 0.9
    term = default.covariance - default.noise_covariance
    assert np.linalg.eigvalsh(term).min() > -1e-12 * np.abs(term).max()  # a covariance: only ever widens
    # Linear in Σ_c: twice the SDs, four times the term (to rounding: 1e-9 of it).
    assert np.allclose(double.covariance - double.noise_covariance, 4 * term, rtol=0, atol=1e-9 * np.abs(term).max())
    k = default.block("p_EL_Ptip")  # the probe tip is what the robot's error moves most (left arm vs right)
    assert np.trace(term[k, k]) > 0.5 * np.trace(default.noise_covariance[k, k])
    with pytest.raises(InputError, match="translation SD"):
        RobotAccuracy(-1e-5)


def test_bootstrap_sees_the_touches(robot, stretched):
    twin, sequential = stretched
    # Resampling the session sees its residuals (noise and the robot error they show), not the
    # stated robot accuracy: compared with the covariance of the residuals' levels alone.
    fit = fit_chain(twin.session, robot, sequential, "sound_speed", robot_accuracy=None)
    boot = bootstrap(twin.session, robot, fit, 200, seed=1)
    for name in ("p_ER_Ntip", "p_EL_Ptip", "sound_speed_m_s"):
        lo, hi = boot.interval(name)
        block = fit.block("scale" if name == "sound_speed_m_s" else name)
        unit = 1540.0 if name == "sound_speed_m_s" else 1.0
        stated = 1.96 * fit.parameter_sd()[block] * unit
        # Percentile half-widths from 200 replicates scatter by ~10 % around the covariance's for
        # linear, Gaussian-like data; images-only resampling gave the tips 0.000-0.048 mm (ratio < 0.5).
        ratio = (np.asarray(hi) - np.asarray(lo)) / 2 / stated
        assert np.all((0.7 < ratio) & (ratio < 1.4)), (name, ratio)


def test_joint_offset_identifiability(robot, stretched):
    twin, sequential = stretched
    fit = fit_chain(twin.session, robot, sequential, "sound_speed")
    ratios = identifiable_joint_offsets(twin.session, robot, fit)
    assert ratios["torso_joint_b1"] < 0.01  # turns both arms together: seen only through the unknown tips
    assert ratios["arm_left_joint_7_t"] < 0.01 and ratios["arm_right_joint_7_t"] < 0.01  # tool transforms absorb it
    assert min(ratios[f"arm_right_joint_{j}"] for j in ("1_s", "2_l", "3_e", "4_u", "5_r", "6_b")) > 0.05


# --- conditioning -----------------------------------------------------------------------------------
def _subset(session, rows):
    rows = np.asarray(rows)
    return replace(
        session,
        samples_q=session.samples_q[rows],
        uv_px=session.uv_px[rows],
        sample_ids=[f"s{i}" for i in range(len(rows))],
    )


def test_samples_at_one_robot_pose_are_refused_not_reported_as_exact(robot, stretched):
    twin, sequential = stretched
    one_pose = _subset(twin.session, np.zeros(64, dtype=int))  # before: predicted landing error 0.000 mm
    for model in MODELS:
        with pytest.raises(DegenerateDataError, match=r"samples\.csv.*not determined.*1 distinct robot pose"):
            fit_chain(one_pose, robot, sequential, model)
    with pytest.raises(DegenerateDataError, match="not determined"):
        calibrate_chain(one_pose, robot, sequential)


def test_samples_without_spread_are_refused(robot, stretched):
    twin, sequential = stretched
    uv = twin.session.uv_px
    patch = _subset(twin.session, np.argsort(np.linalg.norm(uv - uv[0], axis=1))[:4])  # 4 images within ~2 px
    limit = f"limit {np.degrees(ROTATION_SD_LIMIT):.1f}"
    with pytest.raises(DegenerateDataError, match=f"image rotation is determined only to .*{limit}") as refused:
        fit_chain(patch, robot, sequential, "rigid")
    # Both causes are named: too little spread, and a robot off its URDF (the remedy: identify the robot).
    assert "--identify-robot" in str(refused.value) and "spread over the image" in str(refused.value)
    one_pose = _subset(twin.session, np.zeros(64, dtype=int))  # and pixels scattered by 1 px
    jitter = replace(one_pose, uv_px=uv[0] + np.random.default_rng(0).normal(size=(64, 2)))
    with pytest.raises(DegenerateDataError, match=r"samples\.csv"):
        fit_chain(jitter, robot, sequential, "rigid")


def test_samples_in_part_of_the_image_warn_with_the_honest_figure(robot, tmp_path, capsys):
    from conftest import ROOT

    from brachycal.data.session import read_session, write_session

    full = read_session(ROOT / "examples" / "twin_session", robot)
    # 16 images: determined, not across the image (a session stating no sector: the whole image counts)
    write_session(replace(_subset(full, np.arange(16)), sector=None), tmp_path / "session")
    out = tmp_path / "result.json"
    assert main(["calibrate", str(tmp_path / "session"), "--out", str(out), "--solve", "chain", "--quiet"]) == 0
    warned = [line for line in capsys.readouterr().err.splitlines() if "whole chain" in line]
    assert len(warned) == 1 and warned[0].startswith("brachycal: warning: whole chain: predicted landing error up to")
    image_map = json.loads(out.read_text())["chain"]["predicted_landing_rms_mm"]["image_map"]["rms_mm"]
    assert max(image_map) > WARN_LANDING_RMS_MM  # the honest figure is in the result


# --- the command ------------------------------------------------------------------------------------
def test_calibrate_chain_cli_and_locate_with_joint_offsets(tmp_path, capsys):
    from conftest import ROOT

    out = tmp_path / "chain.json"
    session = str(ROOT / "examples" / "twin_session")
    assert (
        main(
            [
                "calibrate",
                session,
                "--out",
                str(out),
                "--solve",
                "chain",
                "--joint-offsets",
                "--bootstrap",
                "5",
                "--robot-accuracy-mm",
                "0.1",
                "--robot-accuracy-deg",
                "0.01",
                "--quiet",
            ]
        )
        == 0
    )
    captured = capsys.readouterr()
    text = captured.out
    assert "warning" not in captured.err  # a session that spans the cube is in the clear
    assert "WHOLE-CHAIN CALIBRATION" in text and "Whole chain" in text and "speed of sound" in text
    assert "axes moves" in text and "assumed" in text  # the axes group's level is said to be assumed
    raw = json.loads(out.read_text())
    chain = raw["chain"]
    assert chain["model"] in MODELS and set(chain["model_selection"]["evidence"]) == set(MODELS)
    assert chain["joint_offsets_rad"] and "bootstrap_spacing_m" in chain["intervals_95"]
    stated = chain["robot_accuracy"]  # what the intervals assumed, as given on the command line
    assert (stated["joint_translation_sd_mm"], stated["joint_rotation_sd_deg"]) == pytest.approx((0.1, 0.01))
    assert "robot accuracy" in chain["intervals_contain"] or "robot_accuracy" in chain["intervals_contain"]
    assert "bootstrap_p_ER_Ntip" in chain["intervals_95"] and "bootstrap_p_EL_Ptip" in chain["intervals_95"]
    assert chain["noise"]["axes"]["source"] == "assumed" and chain["noise"]["image"]["source"] == "residuals"
    assert chain["conditioning"]["rcond"] > chain["conditioning"]["rcond_limit"]
    assert set(raw["transforms"]["Ptip_T_I"]) == {"chain"} and "sequential" in raw
    assert len(raw["loocv"]["chain"]["errors_mm"]) == 64
    joints = tmp_path / "q.csv"
    joints.write_text(
        "time,"
        + (ROOT / "examples" / "joint_log.csv").read_text().splitlines()[0].split(",", 1)[1]
        + "\n"
        + (ROOT / "examples" / "joint_log.csv").read_text().splitlines()[-1]
        + "\n"
    )
    assert main(["locate", str(out), str(joints), "--uv", "540,300", "--method", "chain"]) == 0


def test_optimal_design_is_a_subset_of_the_candidates(robot):
    assert grid_offsets(3, 0.04).shape == (27, 3)
    chosen = optimal_offsets(robot, 10, seed=0)
    candidates = {tuple(np.round(p, 9)) for p in grid_offsets(5, 0.04)}
    assert len({tuple(np.round(p, 9)) for p in chosen}) == 10
    assert all(tuple(np.round(p, 9)) in candidates for p in chosen)


def test_interval_of_a_named_block(robot, stretched):
    twin, sequential = stretched
    fit = fit_chain(twin.session, robot, sequential, "sound_speed")
    low, high = interval(fit, "scale")
    assert low[0] * 1540 < fit.sound_speed_m_s < high[0] * 1540
    assert np.allclose((high - low) / 2, 1.959964 * fit.parameter_sd()[fit.block("scale")], rtol=1e-6)


def test_a_model_the_data_cannot_determine_is_left_out_of_the_choice(robot, stretched, monkeypatch):
    from brachycal.calibration.chain import model_choice
    from brachycal.calibration.metrics import ErrorStats

    twin, sequential = stretched
    n = len(twin.session.uv_px)
    refusal = "whole chain: the pixel scale is not determined by the data"

    def fake_fit(session, robot, initial, model, **kwargs):
        if model == "scaled_uv":
            raise DegenerateDataError(refusal)
        return replace(fit, outliers=np.zeros(n, dtype=bool))

    def fake_cv(session, robot, initial, model, folds=8, seed=0, exclude=None):
        if model == "sound_speed":
            raise DegenerateDataError(refusal)
        return ErrorStats(np.full(n, {"rigid": 3e-4, "similarity": 2e-4}[model]) * (1 + np.arange(n) / n))

    fit = fit_chain(twin.session, robot, sequential, "rigid")
    monkeypatch.setattr(model_choice, "fit_chain", fake_fit)
    monkeypatch.setattr(model_choice, "cross_validate", fake_cv)
    choice = model_choice.select_model(twin.session, robot, sequential)
    assert set(choice.undetermined) == {"scaled_uv", "sound_speed"} and set(choice.cv) == {"rigid", "similarity"}
    assert choice.model == "similarity"  # the better of the determined ones (one SE apart)

    def refuse(*args, **kwargs):
        raise DegenerateDataError(refusal)

    monkeypatch.setattr(model_choice, "cross_validate", refuse)  # no model left
    with pytest.raises(DegenerateDataError, match="not determined"):
        model_choice.select_model(twin.session, robot, sequential)


def test_the_landing_warning_looks_only_inside_the_imaging_sector(robot, monkeypatch):
    # Pixels outside the probe's sector never show a needle: their predicted landing error must not
    # raise the warning, while the same calibration without a stated sector looks at the whole image.
    import warnings

    from conftest import ROOT

    from brachycal.calibration.session import chain_report
    from brachycal.data.session import read_session
    from brachycal.errors import ConditioningWarning

    session = read_session(ROOT / "examples" / "twin_session", robot)
    assert session.sector is not None
    initial = calibrate(session, robot)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConditioningWarning)
        report = calibrate_chain(session, robot, initial)
    inside = session.sector.margin_to_edge(report.fov_px, session.spacing_m) >= 0
    assert 0 < inside.sum() < len(inside)
    in_sector = max(report.predicted_fov_mm[inside].max(), report.predicted_cube_mm.max())
    whole = report.predicted_fov_mm.max()
    assert in_sector < whole  # the corners outside the sector predict the worst landing
    monkeypatch.setattr(chain_report, "WARN_LANDING_RMS_MM", (in_sector + whole) / 2)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ConditioningWarning)
        calibrate_chain(session, robot, initial, choice=report.choice)
    with pytest.warns(ConditioningWarning, match="in the image or at the sample poses"):
        calibrate_chain(replace(session, sector=None), robot, initial, choice=report.choice)
