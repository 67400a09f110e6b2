"""The dual-arm session as a protocol of ``robot identify``: the twin's session identified through
the command, held-out configurations first, the written URDF the identification's robot."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from brachycal.calibration.robot.identification import corrected_robot
from brachycal.cli.main import main
from brachycal.model.description import load_robot

ROOT = Path(__file__).resolve().parents[1]
TWIN = ROOT / "examples" / "twin_session"


def test_cli_prints_held_out_first_and_writes_the_identified_robot(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["robot", "identify", "session", str(TWIN), "--robot", "sda10f", "--out", str(out)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("held-out configurations (8-fold, 64 samples)")
    assert lines[1].startswith("training (")
    assert "combinations identified beyond the prior" in lines[3]
    document = json.loads((out / "identification.json").read_text())
    assert document["protocol"] == "session"
    assert list(document).index("held_out") < list(document).index("training")
    held = document["held_out"]["image_error"]
    assert held["chain_alone"]["samples"] == held["robot_identified"]["samples"] == 64
    # the figures printed are the file's
    assert f"{held['chain_alone']['rmse_mm']:.3f} -> {held['robot_identified']['rmse_mm']:.3f} mm" in lines[0]
    # The verdict last: the example's twin robot is its URDF (no wear to find), so the identification
    # gains nothing beyond chance at held-out configurations and the URDF stays.
    verdict = document["held_out"]["verdict"]
    assert verdict["use_identified_robot"] is False
    assert lines[-2].startswith("verdict: keep the URDF: held-out image error ")
    assert lines[-2].endswith("; use the URDF it started from")
    nominal = load_robot("sda10f")
    c = np.array([[row[k] for k in ("vx", "vy", "vz", "wx", "wy", "wz")] for row in document["corrections"].values()])
    assert np.any(c != 0)
    expected = corrected_robot(nominal, c)
    written = load_robot(str(out / "robot.urdf"))
    Q = np.random.default_rng(0).uniform(nominal.lower, nominal.upper, (5, nominal.nq))
    frames = [nominal.rig.needle_arm.flange, nominal.rig.probe_arm.flange]
    assert np.allclose(written.fk_frames(frames, Q), expected.fk_frames(frames, Q), atol=1e-9)


def test_identify_robot_is_fit_arm_on_the_session_model():
    """The session's identification is the arm core's fit of the session model (fit_session):
    identify_robot's corrections are its estimate and its posterior its covariance, reordered to
    (chain, corrections) and in prior units. The axes moves' few rows (2 residual degrees of
    freedom on the twin) take the touches' level, by the model's noise rule; the chain's fit on
    the corrected robot reports it as assumed."""
    from brachycal.calibration import calibrate
    from brachycal.calibration.chain import MIN_NOISE_DOF
    from brachycal.calibration.robot.identification import identify_robot, prior_sd
    from brachycal.calibration.robot.session_model import fit_session
    from brachycal.calibration.robot_accuracy import RobotAccuracy
    from brachycal.data.session import read_session

    robot = load_robot("sda10f")
    session = read_session(TWIN, robot)
    initial = calibrate(session, robot, ("scaled_uv",))
    accuracy = RobotAccuracy(0.3e-3, float(np.radians(0.03)))
    identified = identify_robot(session, robot, initial, "sound_speed", accuracy)
    arm = fit_session(session, robot, initial, "sound_speed", accuracy).arm
    sd = arm.correction_sd()
    assert np.max(np.abs(arm.corrections / sd)) > 1  # the robot is off: corrections worth comparing
    assert np.max(np.abs(identified.corrections - arm.corrections) / sd) < 1e-6
    p = len(identified.fit.x)
    stated = (np.sqrt(np.diag(identified.posterior)[p:]) * prior_sd(robot, accuracy)).reshape(-1, 6)
    assert np.allclose(stated, sd, rtol=1e-9)
    assert np.allclose(np.sqrt(np.diag(identified.posterior)[:p]), np.sqrt(np.diag(arm.y_covariance())), rtol=1e-9)
    assert arm.noise_dof["axes"] < MIN_NOISE_DOF <= arm.noise_dof["touch"]
    assert arm.sigma["axes"] == arm.sigma["touch"]
    noise = identified.fit.noise
    assert noise["axes"].source == "assumed" and noise["axes"].sd_m == noise["touch"].sd_m
    assert noise["touch"].source == noise["image"].source == "residuals"
