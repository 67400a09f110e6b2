"""The digital twin: exact when noise-free, deterministic by seed, and the paper's figures by default."""

from __future__ import annotations

import shutil
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
from conftest import ROOT

from brachycal.calibration import METHODS, calibrate
from brachycal.cli.main import main
from brachycal.simulation.study import run_study, sweep
from brachycal.simulation.targeting import targeting_error
from brachycal.simulation.twin import TwinConfig, simulate
from brachycal.simulation.twin_files import read_twin, write_twin


@pytest.fixture(scope="module")
def default_twin(robot):
    return simulate(robot, TwinConfig(seed=0))


def test_zero_noise_twin_calibrates_exactly_and_targets_exactly(robot):
    twin = simulate(robot, TwinConfig(seed=3).without_noise())
    result = calibrate(twin.session, robot)
    assert np.abs(result.T_ER_Ntip - twin.truth.T_ER_Ntip).max() < 1e-9
    assert np.abs(result.T_EL_Ptip - twin.truth.T_EL_Ptip).max() < 1e-9
    for method in METHODS:
        assert np.abs(result.image[method].T_Ptip_I - twin.truth.T_Ptip_I).max() < 1e-9, method
    hit = targeting_error(twin, result.T_ER_Ntip, result.T_EL_Ptip, result.image["icp"], n_targets=10)
    assert hit.stats.max_mm < 1e-6


def test_same_seed_same_files_other_seed_other_files(robot, tmp_path):
    names = ["session.toml", "touches.csv", "axes.csv", "samples.csv", "truth.json", "physical_robot.urdf"]
    a = write_twin(simulate(robot, TwinConfig(seed=5)), tmp_path / "a")
    b = write_twin(simulate(robot, TwinConfig(seed=5)), tmp_path / "b")
    c = write_twin(simulate(robot, TwinConfig(seed=6)), tmp_path / "c")
    for name in names:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    assert (a / "samples.csv").read_bytes() != (c / "samples.csv").read_bytes()


def test_each_noise_source_has_its_own_switch_and_stream(robot, default_twin):
    quiet = simulate(robot, replace(TwinConfig(seed=0), annotation_noise=False))
    # Switching annotation noise off changes the pixels only, not the joints.
    assert np.array_equal(quiet.session.samples_q, default_twin.session.samples_q)
    assert not np.array_equal(quiet.session.uv_px, default_twin.session.uv_px)
    still = simulate(robot, replace(TwinConfig(seed=0), encoder_noise=False))
    assert np.array_equal(still.session.samples_q, still.true_samples_q)
    assert np.array_equal(still.session.uv_px, default_twin.session.uv_px)
    assert 1e-6 < np.abs(default_twin.session.samples_q - default_twin.true_samples_q).std() < 1e-4


def test_out_of_plane_offsets_and_pixel_scale_are_what_the_truth_says(default_twin):
    from brachycal.simulation.twin import tip_in_image

    twin = default_twin
    assert np.abs(twin.out_of_plane_m).max() <= 0.3e-3 and np.abs(twin.out_of_plane_m).max() > 0.1e-3
    assert np.isclose(twin.truth.spacing_m[1] / twin.truth.spacing_m[0], 1482 / 1540)
    k = 7
    p = tip_in_image(twin, k)
    assert abs(p[2] - twin.out_of_plane_m[k]) < 1e-9
    true_px = p[:2] / twin.truth.spacing_m
    assert np.abs(true_px - twin.session.uv_px[k]).max() < 6  # 1 px SD annotation noise


def test_default_twin_reproduces_the_papers_figures(robot, default_twin):
    result = calibrate(default_twin.session, robot)
    assert 0.1 < result.needle.validation.mae_mm < 0.4 and 0.1 < result.probe.validation.mae_mm < 0.4  # paper 0.19
    assert 0.5 < result.loocv["kabsch"].mae_mm < 0.8  # paper 0.65
    hits = {
        m: targeting_error(default_twin, result.T_ER_Ntip, result.T_EL_Ptip, result.image[m], 30).stats
        for m in ("kabsch", "scaled_uv")
    }
    assert hits["scaled_uv"].mae_mm < hits["kabsch"].mae_mm / 3  # the stretch is what hurts the rigid fit
    assert hits["kabsch"].mae_mm < result.loocv["kabsch"].mae_mm  # LOO also carries the left-out noise


def test_outliers_are_flagged_in_the_truth(robot):
    twin = simulate(robot, replace(TwinConfig(seed=2), outliers=True))
    rate = twin.outlier.mean()
    assert 0.02 < rate < 0.25
    clean = simulate(robot, TwinConfig(seed=2))
    jump = np.linalg.norm(twin.session.uv_px - clean.session.uv_px, axis=1)
    assert np.all(jump[twin.outlier] >= 15) and np.all(jump[~twin.outlier] == 0)


def test_twin_files_round_trip(robot, default_twin, tmp_path):
    folder = write_twin(default_twin, tmp_path / "t")
    back = read_twin(folder, robot)
    assert np.array_equal(back.session.samples_q, default_twin.session.samples_q)
    assert np.array_equal(back.true_samples_q, default_twin.true_samples_q)
    q = default_twin.true_samples_q[:3]
    assert np.abs(back.physical.fk("needle_tip", q) - default_twin.physical.fk("needle_tip", q)).max() < 1e-12
    assert back.config.annotation_sd_px == default_twin.config.annotation_sd_px


def test_committed_twin_example_is_seed_0(tmp_path):
    copy = tmp_path / "examples"
    shutil.copytree(ROOT / "examples", copy)
    subprocess.run([sys.executable, str(copy / "make_twin_session.py")], check=True, capture_output=True)
    for path in sorted((ROOT / "examples" / "twin_session").iterdir()):
        if path.name == "physical_robot.urdf":
            continue  # its mesh paths point from the copy's location
        assert (copy / "twin_session" / path.name).read_bytes() == path.read_bytes(), path.name


def test_demo_prints_both_tables_and_the_truth_errors_and_writes_the_report(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path), "--targets", "20"]) == 0
    text = capsys.readouterr().out
    for heading in ("TABLE I.", "TABLE II.", "END-TO-END TARGETING ERROR (20 targets", "TABLE III (twin)", "secondary"):
        assert heading in text
    for name in ("fig10_points.png", "fig11_loo_histogram.png", "targeting_errors.png", "residuals.csv"):
        assert (tmp_path / "report" / name).stat().st_size > 1000
    assert (tmp_path / "result.json").exists() and (tmp_path / "session" / "truth.json").exists()
    assert main(["demo", "--example", "--out", str(tmp_path / "ex"), "--targets", "5"]) == 0
    assert "examples/twin_session" in capsys.readouterr().out


def test_study_is_identical_serial_parallel_and_on_dask():
    from distributed import LocalCluster

    runs = sweep(2, [2], [40.0], [1.0], targets=5)
    serial = run_study(runs, workers=1)
    assert len(serial) == 4 and serial[0]["samples"] == 8
    assert run_study(runs, workers=2) == serial
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        assert run_study(runs, scheduler=cluster.scheduler_address) == serial


def test_study_cli_writes_runs_summary_and_plot(tmp_path, capsys):
    args = [
        "study",
        "--out",
        str(tmp_path),
        "--points",
        "2",
        "--annotation-px",
        "1",
        "--seeds",
        "2",
        "--quiet",
        "--targets",
        "5",
        "--workers",
        "1",
    ]
    assert main(args) == 0
    assert "Scaled u/v" in capsys.readouterr().out
    assert len((tmp_path / "runs.csv").read_text().splitlines()) == 1 + 2 * 2
    assert (tmp_path / "study.png").stat().st_size > 1000
    assert main(args) == 2  # never replaces without --force
    assert (
        main(
            [
                "study",
                "--out",
                str(tmp_path / "x"),
                "--scheduler",
                "tcp://127.0.0.1:1",
                "--points",
                "2",
                "--seeds",
                "1",
                "--quiet",
            ]
        )
        == 2
    )
    assert "cannot reach the Dask scheduler" in capsys.readouterr().err


def test_tracker_route_is_exact_without_noise_and_worse_than_fusion_with_it(robot):
    from brachycal.simulation.nwire_twin import T_PTIP_MARKER, NWireSimConfig, tracker_route

    twin = simulate(robot, TwinConfig(seed=0).without_noise())
    route = tracker_route(twin, NWireSimConfig().without_noise())
    assert np.abs(route.T_EL_marker - twin.truth.T_EL_Ptip @ T_PTIP_MARKER).max() < 1e-9
    assert np.abs(route.image.T_Ptip_I - np.linalg.inv(T_PTIP_MARKER) @ twin.truth.T_Ptip_I).max() < 1e-9
    result = calibrate(twin.session, robot, ("kabsch",))
    assert targeting_error(twin, result.T_ER_Ntip, route.T_EL_marker, route.image, 10).stats.max_mm < 1e-6
    noisy = simulate(robot, TwinConfig(seed=0))
    result = calibrate(noisy.session, robot, ("scaled_uv",))
    tracked = tracker_route(noisy, NWireSimConfig(seed=0))
    hit_tracker = targeting_error(noisy, result.T_ER_Ntip, tracked.T_EL_marker, tracked.image, 20).stats
    hit_fusion = targeting_error(noisy, result.T_ER_Ntip, result.T_EL_Ptip, result.image["scaled_uv"], 20).stats
    assert hit_tracker.mae_mm > 3 * hit_fusion.mae_mm
