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

from brachycal.calibration.session.calibrate import calibrate_folder
from brachycal.data import write_bag_log
from brachycal.data.formats.bags import bag_log_blocks
from brachycal.data.formats.csv_log import csv_log_blocks
from brachycal.imaging.needle_tip import detect_tips
from brachycal.studies import run_demo, run_study
from brachycal.studies.demo import DEMO_STAGES
from brachycal.studies.study import sweep

TWIN_SESSION = ROOT / "examples" / "twin_session"
JOINT_LOG = ROOT / "examples" / "joint_log.csv"


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


QUIET = [
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
