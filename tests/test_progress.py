"""Progress: the library's long work reports whole counts that add up to its total (to a callback:
the library never draws a bar), and each long command shows a bar on a terminal's stderr in the
unit it counts ("run", "frame", "resample", bytes...), and nothing with --quiet."""

from __future__ import annotations

import fcntl
import os
import re
import struct
import subprocess
import sys
import termios
import threading
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, random_configurations
from tqdm import tqdm

from brachycal.calibration import calibrate
from brachycal.calibration.robot.evidence import evidence_search
from brachycal.calibration.robot.identification import identify_session
from brachycal.calibration.robot.touches import (
    TOUCHES_ACCURACY,
    evidence_prior,
    identify_touch_folders,
    identify_touches,
    read_places,
)
from brachycal.calibration.robot.tracker import identify_from_tracker, tracker_data, tracker_fits
from brachycal.calibration.robot_accuracy import RobotAccuracy
from brachycal.calibration.session.calibrate import calibrate_folder
from brachycal.data import write_bag_log
from brachycal.data.formats.bags import bag_log_blocks
from brachycal.data.formats.csv_log import csv_log_blocks
from brachycal.data.formats.tracker_table import read_tracker_columns, read_tracker_table
from brachycal.data.session import read_session
from brachycal.errors import DegenerateDataError
from brachycal.imaging.needle_tip import detect_tips
from brachycal.model.description import load_robot
from brachycal.studies import run_demo, run_study
from brachycal.studies.demo import DEMO_STAGES
from brachycal.studies.study import sweep

TWIN_SESSION = ROOT / "examples" / "twin_session"
JOINT_LOG = ROOT / "examples" / "joint_log.csv"
TRACKER = ROOT / "examples" / "tracker"
TOUCHES = ROOT / "examples" / "touches"


def test_study_counts_one_per_run():
    runs = sweep(2, [3], [40.0], [0.5], methods=("kabsch",), targets=2)
    calls: list[int] = []
    rows = run_study(runs, workers=1, progress=calls.append)
    assert len(runs) == 2 and calls == [1, 1]
    assert len(rows) == len(runs)  # one row per run and method: the count is of runs, not rows


def test_demo_counts_its_stages(robot, tmp_path):
    calls: list[int] = []
    run_demo(robot, tmp_path / "demo", example=True, n_targets=5, progress=calls.append)
    assert calls == [1] * len(DEMO_STAGES)


def test_tips_count_one_per_frame():
    frames = np.random.default_rng(0).integers(0, 60, size=(3, 64, 64), dtype=np.uint8)
    calls: list[int] = []
    assert len(detect_tips(frames, progress=calls.append)) == 3
    assert calls == [1, 1, 1]


def test_bootstrap_counts_one_per_resample(robot):
    calls: list[int] = []
    calibrated = calibrate_folder(TWIN_SESSION, robot, chain=True, bootstrap_replicates=4, progress=calls.append)
    assert calls == [1, 1, 1, 1]
    assert calibrated.chain is not None and calibrated.chain.bootstrap is not None
    assert all(len(values) == 4 for values in calibrated.chain.bootstrap.values.values())


def test_tracker_counts_each_model_s_fit_and_its_folds():
    """Per model scored, its fit on all postures and one leave-one-out fold per posture: with
    --model offsets the frames and the offsets, 2 × (N + 1) calls; the figures those without a
    callback give."""
    table = read_tracker_table(TRACKER / "table.csv", read_tracker_columns(TRACKER / "columns.toml"))
    data = tracker_data(load_robot("ur10"), table)
    calls: list[int] = []
    counted = identify_from_tracker(data, model="offsets", progress=calls.append)
    assert tracker_fits(len(data.Q), model="offsets") == 2 * (len(data.Q) + 1)
    assert calls == [1] * tracker_fits(len(data.Q), model="offsets")
    plain = identify_from_tracker(data, model="offsets")
    assert [s.model for s in counted.scores] == [s.model for s in plain.scores] == ["frames", "offsets"]
    for a, b in zip(counted.scores, plain.scores, strict=True):
        assert np.allclose(a.loo_errors_m, b.loo_errors_m, rtol=0, atol=1e-12)
    assert np.allclose(counted.fit.corrections, plain.fit.corrections, rtol=0, atol=1e-12)


def test_evidence_search_counts_each_fit_refused_or_not():
    """One call per fit the search makes (a fit the data refuse too), however many it takes; the
    choice the one without a callback makes."""
    fits: list[int] = []

    def log_evidence(accuracy: RobotAccuracy, extra: tuple[float, ...]) -> float:
        fits.append(1)
        if accuracy.translation_sd_m > 3e-3:
            raise DegenerateDataError("refused")
        t, r = np.log(accuracy.translation_sd_m / 2e-4), np.log(accuracy.rotation_sd_rad / 3e-3)
        return -(t**2) - r**2 - np.log(extra[0] / 2.0) ** 2

    start = RobotAccuracy(1e-3, 1e-2)
    calls: list[int] = []
    counted = evidence_search(log_evidence, start, (1.0,), source="test", progress=calls.append)
    assert len(fits) > 10 and calls == [1] * len(fits) == [1] * counted.evaluations
    assert counted == evidence_search(log_evidence, start, (1.0,), source="test")


def test_touches_count_each_fit_of_the_evidence_search_and_the_last():
    """With the evidence, one call per fit of the search and one for the fit at its choice (the
    search's own count and one); the prior chosen the one without a callback."""
    robot = load_robot("panda")
    flange, T_flange_tool = robot.tool_transform("panda_hand_tcp")
    places = read_places(robot, flange, [TOUCHES / "front"], {(0, 1): 0.05})
    tip = T_flange_tool[:3, 3]
    calls: list[int] = []
    result = identify_touches(robot, places, flange, TOUCHES_ACCURACY, tip=tip, prior="evidence", progress=calls.append)
    chosen = evidence_prior(robot, places, flange, TOUCHES_ACCURACY, tip=tip)
    assert chosen.evaluations > 1 and calls == [1] * (chosen.evaluations + 1)
    assert result.fit.accuracy == chosen.accuracy


def test_touch_folders_count_the_compliance_fit_and_the_urdf_fit():
    """--dynamics with the stated prior: two fits (geometry with compliance, geometry alone)."""
    robot = load_robot("panda")
    folders = [TOUCHES / name for name in ("front", "left")]
    calls: list[int] = []
    args = (robot, folders, "panda_hand_tcp", ["front"], TOUCHES_ACCURACY)
    report = identify_touch_folders(*args, dynamics=robot, progress=calls.append)
    assert report.urdf_fit is not None and calls == [1, 1]


def test_session_identification_counts_itself_and_each_fold(robot):
    session = read_session(TWIN_SESSION, robot)
    initial = calibrate(session, robot, ("scaled_uv",))
    calls: list[int] = []
    accuracy = RobotAccuracy(3e-5, 5e-5)
    result = identify_session(session, robot, initial, accuracy, folds=3, progress=calls.append)
    assert result.folds == 3 and calls == [1] * 4


def _csv_log(path: Path, robot, n: int, *, end: str = "\n") -> Path:
    Q = random_configurations(robot, n, seed=3) * 0.9
    lines = [",".join(["time", *robot.joint_names])]
    lines += [",".join(repr(float(v)) for v in [1.7e9 + 0.004 * k, *q]) for k, q in enumerate(Q)]
    path.write_text("\n".join(lines) + end)
    return path


@pytest.mark.parametrize("end", ["\n", "\n\n"], ids=["line-break-at-end", "blank-line-at-end"])
@pytest.mark.parametrize("block_bytes", [1_000, 1 << 20], ids=["many-blocks", "one-block"])
def test_csv_log_counts_the_bytes_of_the_file(tmp_path, robot, end, block_bytes):
    path = _csv_log(tmp_path / "log.csv", robot, 103, end=end)
    calls: list[int] = []
    samples = sum(len(q) for _, q in csv_log_blocks(path, robot, block_bytes=block_bytes, progress=calls.append))
    assert samples == 103
    assert all(isinstance(n, int) and n > 0 for n in calls)
    assert sum(calls) == path.stat().st_size
    assert (len(calls) > 30) == (block_bytes == 1_000)


def test_csv_log_with_quoted_fields_counts_the_bytes_of_the_file(tmp_path, robot):
    path = _csv_log(tmp_path / "log.csv", robot, 20)
    header, *rows = path.read_text().splitlines()
    path.write_text("\n".join([header, *(f'"{row.split(",")[0]}",{row.split(",", 1)[1]}' for row in rows)]) + "\n")
    calls: list[int] = []
    assert sum(len(q) for _, q in csv_log_blocks(path, robot, block_bytes=1_000, progress=calls.append)) == 20
    assert sum(calls) == path.stat().st_size


def test_bag_counts_its_messages_and_says_their_number_first(tmp_path, robot):
    Q = random_configurations(robot, 50, seed=7) * 0.9
    bag = tmp_path / "log"
    write_bag_log(bag, 1.7e9 + np.arange(50) * 0.004, Q, robot.joint_names, ros=2, storage="sqlite3")
    events: list[tuple[str, int]] = []
    blocks = bag_log_blocks(
        bag,
        robot,
        block_messages=7,
        progress=lambda n: events.append(("done", n)),
        total=lambda n: events.append(("total", n)),
    )
    assert sum(len(q) for _, q in blocks) == 50
    assert events[0] == ("total", 50)
    assert [n for kind, n in events[1:]] == [7] * 7 + [1] and all(kind == "done" for kind, _ in events[1:])


def run_on_a_terminal(argv: list[str], cwd: Path) -> tuple[int, str, str]:
    """Run ``brachycal ARGV`` in a new process whose stderr is a pseudo-terminal (80 columns):
    ``(exit code, stdout, what the terminal received)``."""
    master, slave = os.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 80, 0, 0))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT / "src"), os.environ.get("PYTHONPATH", "")])}
    env.pop("TQDM_DISABLE", None)
    process = subprocess.Popen(
        [sys.executable, "-m", "brachycal.cli.main", *argv],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=slave,
        cwd=cwd,
        env=env,
    )
    os.close(slave)
    received: list[bytes] = []

    def drain() -> None:  # while it runs: a full terminal buffer would block the command
        while True:
            try:
                data = os.read(master, 4096)
            except OSError:  # EIO: every writer has closed the terminal
                return
            if not data:
                return
            received.append(data)

    reader = threading.Thread(target=drain)
    reader.start()
    try:
        out, _ = process.communicate(timeout=300)
    finally:
        reader.join(timeout=10)
        os.close(master)
    return process.returncode, out.decode(), b"".join(received).decode(errors="replace")


STUDY = ["study", "--out", "study", "--seeds", "2", "--points", "3", "--annotation-px", "0.5"]
STUDY += ["--methods", "kabsch", "--workers", "1", "--targets", "2"]


def test_study_bar_counts_whole_runs_on_a_terminal(tmp_path):
    code, out, terminal = run_on_a_terminal(STUDY, tmp_path)
    assert code == 0, terminal
    assert "study: 2 runs" in out
    assert re.search(r"study: +\d+%\|.*\| 1/2 \[", terminal), terminal  # whole runs, not "1.00/2.00"
    assert "run/s" in terminal and "sample" not in terminal


def test_fk_bar_counts_bytes_on_a_terminal(tmp_path):
    code, _, terminal = run_on_a_terminal(
        ["fk", str(JOINT_LOG), "--frames", "needle_tip", "--out", "poses.csv"], tmp_path
    )
    assert code == 0, terminal
    total = tqdm.format_sizeof(JOINT_LOG.stat().st_size)  # "97.0k": bytes scaled as the bar shows them
    assert "reading log" in terminal and f"/{total} [" in terminal, terminal  # its total: the file's size
    assert "B/s" in terminal and "sample" not in terminal


def test_fk_bar_counts_messages_of_a_bag_on_a_terminal(tmp_path, robot):
    Q = random_configurations(robot, 50, seed=7) * 0.9
    write_bag_log(tmp_path / "log", 1.7e9 + np.arange(50) * 0.004, Q, robot.joint_names, ros=2, storage="sqlite3")
    code, _, terminal = run_on_a_terminal(["fk", "log", "--frames", "needle_tip", "--out", "poses.csv"], tmp_path)
    assert code == 0, terminal
    assert "reading bag" in terminal and "message/s" in terminal, terminal


def test_calibrate_bar_counts_resamples_on_a_terminal(tmp_path):
    argv = ["calibrate", str(TWIN_SESSION), "--solve", "chain", "--bootstrap", "3", "--out", "r.json"]
    code, _, terminal = run_on_a_terminal(argv, tmp_path)
    assert code == 0, terminal
    assert re.search(r"bootstrap: +\d+%\|.*\| \d/3 \[", terminal) and "resample/s" in terminal, terminal


TRACKER_RUN = ["robot", "identify", "tracker", str(TRACKER / "table.csv"), "--columns", str(TRACKER / "columns.toml")]
TRACKER_RUN += ["--robot", "ur10", "--model", "offsets", "--out", "tracker"]
TOUCHES_RUN = ["robot", "identify", "touches", *(str(TOUCHES / n) for n in ("front", "left"))]
TOUCHES_RUN += ["--robot", "panda", "--train", "front", "--dynamics", "panda", "--out", "touches"]


def test_robot_identify_bars_on_a_terminal(tmp_path):
    """The tracker counts its fits to a known total (2 models × 25); the touches count theirs without one."""
    code, _, terminal = run_on_a_terminal(TRACKER_RUN, tmp_path)
    assert code == 0, terminal
    assert re.search(r"leave-one-out: +\d+%\|.*\| \d+/50 \[", terminal) and "fit/s" in terminal, terminal
    code, _, terminal = run_on_a_terminal(TOUCHES_RUN, tmp_path)
    assert code == 0, terminal
    assert re.search(r"identifying: \d+fit \[", terminal) and "fit/s" in terminal, terminal


QUIET = [
    pytest.param([*TRACKER_RUN, "--quiet"], id="robot-identify-tracker"),
    pytest.param([*TOUCHES_RUN, "--quiet"], id="robot-identify-touches"),
    pytest.param(
        ["robot", "identify", "session", str(TWIN_SESSION), "--robot", "sda10f", "--out", "session", "--quiet"],
        id="robot-identify-session",
    ),
    pytest.param([*STUDY, "--quiet"], id="study"),
    pytest.param(["fk", str(JOINT_LOG), "--frames", "needle_tip", "--out", "poses.csv", "--quiet"], id="fk"),
    pytest.param(
        ["calibrate", str(TWIN_SESSION), "--solve", "chain", "--bootstrap", "3", "--out", "r.json", "--quiet"],
        id="calibrate-bootstrap",
    ),
    pytest.param(["demo", "--example", "--out", "demo", "--quiet"], id="demo"),
    pytest.param(["demo", "--table3", "--seeds", "1", "--targets", "5", "--quiet"], id="demo-table3"),
]


@pytest.mark.parametrize("argv", QUIET)
def test_quiet_prints_nothing_on_a_terminals_stderr(tmp_path, argv):
    code, _, terminal = run_on_a_terminal(argv, tmp_path)
    assert code == 0, terminal
    assert terminal == "", terminal


@pytest.mark.slow  # the recording's images: ~10 s
def test_tips_and_demo_bars_on_a_terminal(tmp_path):
    code, _, terminal = run_on_a_terminal(["demo", "--out", "run", "--recording", "--images"], tmp_path)
    assert code == 0, terminal
    assert re.search(r"demo: +\d+%\|.*\| \d/5 \[", terminal) and "stage/s" in terminal, terminal
    frames = str(tmp_path / "run" / "recording" / "frames.mha")
    code, _, terminal = run_on_a_terminal(["tips", frames, "--out", "images.csv"], tmp_path)
    assert code == 0, terminal
    assert "tips:" in terminal and "frame/s" in terminal, terminal
    code, _, terminal = run_on_a_terminal(["tips", frames, "--out", "again.csv", "--quiet"], tmp_path)
    assert code == 0 and terminal == "", terminal


def test_stepper_image_counts_one_per_frame_of_each_recording():
    """``stepper image``'s segmentation reports each recording's frames, one by one, and the result is
    the same with and without the callback."""
    from contextlib import contextmanager

    from brachycal.calibration.phantom.stepper_probe import calibrate_stepper_image_files
    from brachycal.data.formats.metaimage import read_sequence_header

    folder = ROOT / "examples" / "stepper"
    files = [
        folder / f"twin_{name}.igs.mha"
        for name in ("ProbeRotation", "RandomStepperMotionCalibration", "RandomStepperMotionValidation")
    ]
    counts: dict[str, list[int]] = {}

    class Counter:
        def __init__(self, name: str) -> None:
            self.name = name

        def update(self, n: int) -> None:
            counts[self.name].append(n)

    @contextmanager
    def progress(name: str, frames: int):
        counts[name] = [frames]
        yield Counter(name)

    config = folder / "PlusDeviceSet_twin_iCal.xml"
    with_bar = calibrate_stepper_image_files(config, *files, progress=progress)
    without = calibrate_stepper_image_files(config, *files)
    assert set(counts) == {f.name for f in files}
    for f in files:
        total, *steps = counts[f.name]
        assert total == int(read_sequence_header(f)[0]["DimSize"].split()[2])
        assert steps == [1] * total
    assert with_bar.to_json() == without.to_json()
