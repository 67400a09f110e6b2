"""The clock lag where it matters: session build and fk --times on a twin recording whose frames
are stamped by an ultrasound clock that lags and drifts."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hostile import run_cli

from brachycal.data.session_build import ImageSettings, build_session
from brachycal.errors import BrachycalWarning, InputError
from brachycal.simulation import RecordingConfig, TwinConfig, record, write_recording

#: The log lags the ultrasound clock by 0.4 s, and the ultrasound clock runs 50 ppm fast (30 ms
#: over this ~600 s recording). The frames are held 1.6 s at each stop and captured 0.75–0.85 s
#: into the hold: 0.4 s moves every still window 0.15–0.05 s into the move before it.
LAG_S = 0.4
DRIFT_PPM = 50.0


@pytest.fixture(scope="module")
def lagged(robot):
    config = RecordingConfig(rate_hz=25.0, hold_s=1.6, image_lag_s=LAG_S, image_clock_drift_ppm=DRIFT_PPM)
    return record(robot, TwinConfig(seed=1, encoder_noise=False), config)


def build(rec, robot, **lag):
    s = rec.session
    return build_session(
        rec.joint_log(),
        rec.marks,
        rec.frames,
        robot=robot,
        settings=ImageSettings(s.spacing_m, s.size_px, s.p_ER_Mtip),
        **lag,
    )


def test_frames_are_stamped_on_the_lagging_drifting_clock(lagged):
    rec = lagged.recording
    t = rec.start_time_s + 200.0
    assert rec.image_time(t) == pytest.approx(t - LAG_S + DRIFT_PPM * 1e-6 * 200.0, abs=1e-9)


def test_without_the_lag_the_build_refuses_with_it_the_session_is_the_truth(lagged, robot):
    # Without --lag-s every frame's still window reaches into a move: refused, not a wrong pose.
    with pytest.raises(InputError, match="moving"):
        build(lagged, robot)
    built = build(lagged, robot, lag_s=LAG_S)
    # Noise-free twin: the still windows hold the stops' joints exactly (1e-12 rad: rounding of a
    # mean of ~25 equal readings); the ≤ 30 ms drift left after the lag stays inside the holds.
    np.testing.assert_allclose(built.session.samples_q, lagged.session.samples_q, rtol=0, atol=1e-12)
    assert built.report.lag_s == LAG_S
    assert built.report.as_json()["clock"] == {"lag_s": LAG_S, "lag_sd_s": 0.0, "lag_sensitive": []}


def test_frames_within_the_lags_uncertainty_of_motion_are_warned_about(lagged, robot):
    # 2 SD = 0.4 s moves each still window past the 0.25 s margin, into the move before or after
    # the hold where that move is fast enough to count as motion.
    with pytest.warns(BrachycalWarning, match="depends on the clock lag"):
        uncertain = build(lagged, robot, lag_s=LAG_S, lag_sd_s=0.2)
    log = lagged.joint_log()
    speed = np.abs(np.diff(log.q, axis=0) / np.diff(log.time)[:, None]).max(axis=1)  # noise-free: true speeds
    still_limit = 1e-3  # rad/s, the build's default still speed
    for entry in uncertain.report.frames_used:
        # The shifted still windows cover the frame's time ± 0.9 s (0.5 s half window + 2 SD);
        # the build judges speed as 0.2 s slopes, so motion well inside (± 0.7 s) must be seen and
        # none at all within ± 0.95 s (one 25 Hz reading beyond) must not be reported.
        inner = np.abs(log.time[:-1] - entry.time_s) < 0.7
        outer = np.abs(log.time[:-1] - entry.time_s) < 0.95
        if speed[inner].max() > 3 * still_limit:
            assert entry.what in uncertain.report.lag_sensitive
        if speed[outer].max() < still_limit / 3:
            assert entry.what not in uncertain.report.lag_sensitive
    assert len(uncertain.report.lag_sensitive) > len(uncertain.report.frames_used) // 2
    # 2 SD = 20 ms stays inside the 0.25 s margin (less the ≤ 30 ms drift): no warning.
    with warnings.catch_warnings():
        warnings.simplefilter("error", BrachycalWarning)
        certain = build(lagged, robot, lag_s=LAG_S, lag_sd_s=0.01)
    assert certain.report.lag_sensitive == ()


def test_session_build_command_takes_the_lag(lagged, tmp_path):
    folder = write_recording(lagged, tmp_path / "rec")
    argv = ["session", "build", str(folder / "joint_log.csv"), "--marks", str(folder / "marks.csv")]
    argv += ["--images", str(folder / "images.csv"), "--plan", str(folder / "plan.csv")]
    argv += ["--template", str(folder / "session.toml")]
    refused = run_cli([*argv, "--out", str(tmp_path / "a")])
    assert refused.code == 2 and "moving" in refused.err
    done = run_cli([*argv, "--lag-s", str(LAG_S), "--out", str(tmp_path / "b")])
    assert done.code == 0, done.err


def test_fk_times_with_the_lag_gives_the_true_pose_during_motion(lagged, tmp_path):
    """Frames taken while the probe moves (freehand-like): the pose at the frame's own stamp is
    off by the probe's travel in 0.4 s; read at stamp + lag it is the true pose up to the log's
    linear interpolation between 25 Hz readings."""
    folder = write_recording(lagged, tmp_path / "rec")
    log = lagged.joint_log()
    path = lagged.twin.nominal.fk("probe_tip", log.q)[:, :3, 3]
    probe_speed = np.linalg.norm(np.diff(path, axis=0), axis=1) / np.diff(log.time)
    moving = np.flatnonzero(probe_speed > 0.5 * probe_speed.max())[::3][:20]  # the probe's fastest stretches
    t_log = log.time[moving]
    stamps = np.array([lagged.recording.image_time(t) for t in t_log])
    (tmp_path / "times.csv").write_text("time\n" + "".join(f"{t:.6f}\n" for t in stamps))
    truth = path[moving]

    def positions(*lag: str) -> np.ndarray:
        out = tmp_path / f"poses{len(lag)}.csv"
        argv = ["fk", str(folder / "joint_log.csv"), "--frames", "probe_tip", "--times", str(tmp_path / "times.csv")]
        outcome = run_cli([*argv, *lag, "--out", str(out), "--quiet"])
        assert outcome.code == 0, outcome.err
        rows = np.loadtxt(out, delimiter=",", skiprows=1, usecols=(0, 2, 3, 4))
        np.testing.assert_allclose(rows[:, 0], stamps, atol=1e-6)  # the table keeps the frames' stamps
        return rows[:, 1:]

    without = np.linalg.norm(positions() - truth, axis=1)
    lag = [f"{LAG_S - DRIFT_PPM * 1e-6 * (t - lagged.recording.start_time_s):.9f}" for t in t_log[:1]]
    with_lag = np.linalg.norm(positions("--lag-s", lag[0]) - truth, axis=1)
    # Without the lag: the probe's travel in 0.4 s at its fastest (measured 58–103 mm).
    assert without.min() > 10e-3
    # With it (the lag at the first frame): the drift left (≤ 30 ms of motion over the recording)
    # and interpolation between 25 Hz readings; measured 0.03 mm, bound 1 mm (a tenth of the bound above).
    assert with_lag.max() < 1e-3
