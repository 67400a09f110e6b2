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
    nominal = load_robot("sda10f")
    c = np.array([[row[k] for k in ("vx", "vy", "vz", "wx", "wy", "wz")] for row in document["corrections"].values()])
    assert np.any(c != 0)
    expected = corrected_robot(nominal, c)
    written = load_robot(str(out / "robot.urdf"))
    Q = np.random.default_rng(0).uniform(nominal.lower, nominal.upper, (5, nominal.nq))
    frames = [nominal.rig.needle_arm.flange, nominal.rig.probe_arm.flange]
    assert np.allclose(written.fk_frames(frames, Q), expected.fk_frames(frames, Q), atol=1e-9)


def test_fit_arm_on_the_session_model_reproduces_the_session_estimator():
    """The session as a ResidualModel of fit_arm (session_arm_fit) gives the corrections of the
    session's own estimator (identify_robot) on the twin: within 0.15 of their posterior SD each
    (measured 0.03 at the default accuracy, 0.07 at 0.3 mm / 0.03°), the SDs within 5 % (measured
    1-4 %; the two differ in the axes moves' noise rule: pooled with the touches here, assigned
    the touches' level there)."""
    from brachycal.calibration import calibrate
    from brachycal.calibration.robot.identification import identify_robot, prior_sd
    from brachycal.calibration.robot.session_model import session_arm_fit
    from brachycal.calibration.robot_accuracy import RobotAccuracy
    from brachycal.data.session import read_session

    robot = load_robot("sda10f")
    session = read_session(TWIN, robot)
    initial = calibrate(session, robot, ("scaled_uv",))
    accuracy = RobotAccuracy(0.3e-3, float(np.radians(0.03)))
    old = identify_robot(session, robot, initial, "sound_speed", accuracy)
    new = session_arm_fit(session, robot, initial, "sound_speed", accuracy)
    scale = prior_sd(robot, accuracy)
    old_sd = (np.sqrt(np.diag(old.posterior)[-6 * robot.nq :]) * scale).reshape(-1, 6)
    assert np.max(np.abs(old.corrections / old_sd)) > 1  # the robot is off: corrections worth comparing
    assert np.max(np.abs(new.corrections - old.corrections) / old_sd) < 0.15
    assert np.allclose(new.correction_sd(), old_sd, rtol=0.05)
    assert new.identifiability.structural_rank == old.identifiability.structural_rank
    assert abs(new.identifiability.identified - old.identifiability.identified) <= 2
