"""Whole-chain calibration: exactness, robustness, model choice, honest uncertainty, designs."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from brachycal.calibration import calibrate
from brachycal.calibration.chain import MODELS, fit_chain, identifiable_joint_offsets, select_model
from brachycal.calibration.uncertainty import inside_ellipsoid, interval, landing_covariance
from brachycal.cli.main import main
from brachycal.simulation.design import grid_offsets, optimal_offsets
from brachycal.simulation.targeting import targeting_error
from brachycal.simulation.twin import TwinConfig, simulate


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
        assert np.abs(fit.T_EL_Ptip @ fit.image.T_Ptip_I - twin.truth.T_EL_Ptip @ twin.truth.T_Ptip_I).max() < 1e-9
        assert np.abs(fit.image.spacing_m - twin.truth.spacing_m).max() < 1e-15
        assert not fit.outliers.any()


def test_chain_beats_the_papers_rigid_method_fourfold_under_a_4_percent_stretch(robot, stretched):
    twin, sequential = stretched
    choice = select_model(twin.session, robot, sequential)
    assert choice.model in ("scaled_uv", "sound_speed")
    fit = fit_chain(twin.session, robot, sequential, choice.model)
    assert abs(fit.sound_speed_m_s - 1482) < 15  # the speed of sound is measured, not assumed
    chain = targeting_error(twin, fit.T_ER_Ntip, fit.T_EL_Ptip, fit.image, 30).stats
    paper = targeting_error(twin, sequential.T_ER_Ntip, sequential.T_EL_Ptip, sequential.image["kabsch"], 30).stats
    assert chain.mae_mm <= paper.mae_mm / 4


def test_gross_outliers_are_flagged_and_barely_matter(robot):
    clean = simulate(robot, TwinConfig(seed=2))
    dirty = simulate(robot, replace(TwinConfig(seed=2), outliers=True))
    assert dirty.outlier.sum() >= 3
    hits = []
    for twin in (clean, dirty):
        initial = calibrate(twin.session, robot, ("scaled_uv",))
        fit = fit_chain(twin.session, robot, initial, "sound_speed")
        hits.append(targeting_error(twin, fit.T_ER_Ntip, fit.T_EL_Ptip, fit.image, 30).stats.mae_mm)
        assert np.array_equal(fit.outliers, twin.outlier)
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


def test_stated_95_percent_intervals_cover_the_truth(robot):
    runs, covered_c, inside, total = 8, 0, 0, 0
    for seed in range(runs):
        twin = simulate(robot, TwinConfig(seed=10 + seed))
        fit = fit_chain(twin.session, robot, calibrate(twin.session, robot, ("scaled_uv",)), "sound_speed")
        low, high = interval(fit, 24)
        covered_c += low * 1540 <= 1482 <= high * 1540
        hit = targeting_error(twin, fit.T_ER_Ntip, fit.T_EL_Ptip, fit.image, 15)
        C = landing_covariance(fit, robot, twin.session.spacing_m, hit.q_read, hit.uv_px)
        ok = inside_ellipsoid(hit.landed_m - hit.targets_m, C)
        inside, total = inside + ok.sum(), total + len(ok)
    assert covered_c >= runs - 2
    assert 0.85 <= inside / total <= 1.0


def test_joint_offset_identifiability(robot, stretched):
    twin, sequential = stretched
    fit = fit_chain(twin.session, robot, sequential, "sound_speed")
    ratios = identifiable_joint_offsets(twin.session, robot, fit)
    assert ratios["torso_joint_b1"] < 0.01  # turns both arms together: seen only through the unknown tips
    assert ratios["arm_left_joint_7_t"] < 0.01 and ratios["arm_right_joint_7_t"] < 0.01  # tool transforms absorb it
    assert min(ratios[f"arm_right_joint_{j}"] for j in ("1_s", "2_l", "3_e", "4_u", "5_r", "6_b")) > 0.05


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
                "--method",
                "chain",
                "--joint-offsets",
                "--bootstrap",
                "5",
                "--quiet",
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "WHOLE-CHAIN CALIBRATION" in text and "Whole chain" in text and "speed of sound" in text
    raw = json.loads(out.read_text())
    chain = raw["chain"]
    assert chain["model"] in MODELS and set(chain["model_selection"]["evidence"]) == set(MODELS)
    assert chain["joint_offsets_rad"] and "bootstrap_spacing_m" in chain["intervals_95"]
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
