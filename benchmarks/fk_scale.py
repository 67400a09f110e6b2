"""``brachycal fk`` on long joint logs (issue 13), beside the plain peer, in one run.

Run: ``make bench`` (or ``.venv/bin/python benchmarks/fk_scale.py``). Generates its own logs in a
temporary folder: 100,000 rows (full-precision numbers, ~31 MB, as a logger writes them) and
2,000,000 rows of CSV, and the 100,000 rows as a ROS 1 bag, a ROS 2 sqlite3 bag and a ROS 2 MCAP
bag. Every command runs as a subprocess, so start-up and peak memory (``ru_maxrss`` of that
process, from ``os.wait4``) are real. Figures (``benchmarks/timing.record``):

- ``fk 100k CSV``: wall time beside the peer ``fk_peer.py`` (``genfromtxt`` + a per-row Pinocchio
  loop writing the same table) on the same log; goal ≤ 0.2 × the peer.
- ``fk 2M CSV``: wall time (goal ≤ 20 s) and peak memory (goal ≤ 500 MB).
- ``fk 100k <bag kind>``: wall time beside ``fk 100k CSV``; goal ≤ 2 × the CSV path.
- ``locate 2M CSV``: peak memory of ``brachycal locate`` (one needle-tip pixel for every row of
  the 2,000,000-row log, with a result calibrated on the bundled exact session); goal ≤ 500 MB,
  beside ``fk`` on the same log (the command streams its configurations as ``fk`` does).

Also checks the results: brachycal's pose table equals the peer's number for number, to one unit
of the last printed decimal (1e-9 m; both print 9 decimals of metres and 12 of quaternions, and a
1e-12 m difference between the batch path and Pinocchio can move a rounding by one unit), and the
bags give the CSV's poses.
"""

from __future__ import annotations

import itertools
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from timing import record

from brachycal.data import write_bag_log
from brachycal.model import Robot

FRAMES = "needle_tip,probe_tip"
BIN = Path(sys.executable).parent
HERE = Path(__file__).parent


def make_log(path: Path, rows: int, robot: Robot, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A CSV joint log of random configurations, numbers at full precision (``%.17g``); returns
    the first 100,000 samples ``(time (n,), q (n, nq))`` for the bags."""
    rng = np.random.default_rng(seed)
    first = None
    with path.open("w") as handle:
        handle.write("time," + ",".join(robot.joint_names) + "\n")
        for start in range(0, rows, 100_000):
            n = min(100_000, rows - start)
            t = 1.7e9 + np.arange(start, start + n) * 0.001
            Q = rng.uniform(robot.lower, robot.upper, size=(n, robot.nq))
            np.savetxt(handle, np.column_stack([t, Q]), fmt="%.17g", delimiter=",")
            first = first or (t, Q)
    assert first is not None
    return first


#: The subprocesses' environment: compiled bytecode cached (in a folder of the run, not the source
#: tree), as in an installed package, even where PYTHONDONTWRITEBYTECODE is set (it makes every
#: start-up compile brachycal's sources again, ~0.15 s that no installation pays).
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def run(argv: list[str], repeats: int = 3) -> tuple[float, float]:
    """Shortest wall time (s) of ``repeats`` runs of one subprocess (the least disturbed run on a
    shared machine) and its largest peak resident memory (MB)."""
    wall, peak = float("inf"), 0.0
    for _ in range(repeats):
        start = time.perf_counter()
        process = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=ENV)
        _, status, usage = os.wait4(process.pid, 0)
        wall = min(wall, time.perf_counter() - start)
        peak = max(peak, usage.ru_maxrss / 1024)  # ru_maxrss is in KiB on Linux
        err = process.stderr.read().decode() if process.stderr else ""
        if os.waitstatus_to_exitcode(status) != 0:
            raise SystemExit(f"{' '.join(argv)} failed: {err}")
    return wall, peak


def fk(log: Path, out: Path, repeats: int = 3) -> tuple[float, float]:
    argv = [str(BIN / "brachycal"), "fk", str(log), "--frames", FRAMES, "--out", str(out), "--quiet", "--force"]
    return run(argv, repeats)


def numbers(path: Path) -> np.ndarray:
    return np.loadtxt(path, delimiter=",", skiprows=1, usecols=(0, 2, 3, 4, 5, 6, 7, 8))


def main() -> None:
    robot = Robot.load()
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        small, big = tmp / "log100k.csv", tmp / "log2M.csv"
        ENV["PYTHONPYCACHEPREFIX"] = str(tmp / "pycache")
        t, Q = make_log(small, 100_000, robot)
        print(f"logs: {small.stat().st_size / 1e6:.0f} MB (100,000 rows)", flush=True)
        tiny = tmp / "tiny.csv"  # a first, untimed run of each compiles and caches the bytecode
        with small.open() as handle:
            tiny.write_text("".join(itertools.islice(handle, 3)))
        fk(tiny, tmp / "tiny_poses.csv", repeats=1)
        run([sys.executable, str(HERE / "fk_peer.py"), str(tiny), str(tmp / "tiny_peer.csv"), FRAMES], repeats=1)

        peer_s, _ = run([sys.executable, str(HERE / "fk_peer.py"), str(small), str(tmp / "peer.csv"), FRAMES])
        csv_s, csv_mb = fk(small, tmp / "poses.csv")
        record(
            "fk 100k CSV",
            csv_s,
            "s",
            goal="<= 0.2 x the plain genfromtxt + per-row Pinocchio loop",
            met=csv_s <= 0.2 * peer_s,
            peer="genfromtxt + Pinocchio loop",
            peer_value=peer_s,
        )
        difference = np.abs(numbers(tmp / "poses.csv") - numbers(tmp / "peer.csv")).max()
        print(f"  largest difference from the peer's table: {difference:.1e} (m, s or quaternion units)")
        assert difference <= 1e-9, "brachycal fk and the plain loop disagree"

        for kind, make in (
            ("ROS 1 bag", lambda p: write_bag_log(p, t, Q, robot.joint_names, ros=1)),
            ("ROS 2 sqlite3 bag", lambda p: write_bag_log(p, t, Q, robot.joint_names, ros=2)),
            ("ROS 2 MCAP bag", lambda p: write_bag_log(p, t, Q, robot.joint_names, ros=2, storage="mcap")),
        ):
            bag = tmp / kind.replace(" ", "_").lower()
            if kind == "ROS 1 bag":
                bag = bag.with_suffix(".bag")
            make(bag)
            bag_s, _ = fk(bag, tmp / "bag_poses.csv")
            record(
                f"fk 100k {kind}",
                bag_s,
                "s",
                goal="<= 2 x the CSV path",
                met=bag_s <= 2 * csv_s,
                peer="brachycal fk on the CSV log",
                peer_value=csv_s,
            )
            from_bag, from_csv = numbers(tmp / "bag_poses.csv"), numbers(tmp / "poses.csv")
            # stamps hold whole nanoseconds (the CSV's times differ by up to 1 ulp of 1.7e9 s, 2.4e-7 s);
            # the joint positions are the same doubles, so the poses are the same text
            assert np.abs(from_bag[:, 0] - from_csv[:, 0]).max() < 1e-6, kind
            assert np.array_equal(from_bag[:, 1:], from_csv[:, 1:]), kind

        make_log(big, 2_000_000, robot, seed=1)
        print(f"logs: {big.stat().st_size / 1e6:.0f} MB (2,000,000 rows)", flush=True)
        big_s, big_mb = fk(big, tmp / "poses2M.csv", repeats=2)
        record("fk 2M CSV time", big_s, "s", goal="<= 20 s", met=big_s <= 20)
        record(
            "fk 2M CSV peak memory",
            big_mb,
            "MB",
            goal="<= 500 MB, independent of the log's length",
            met=big_mb <= 500,
            peer="brachycal fk on 100k rows",
            peer_value=csv_mb,
        )

        result = tmp / "result.json"
        session = HERE.parent / "examples" / "session_exact"
        run([str(BIN / "brachycal"), "calibrate", str(session), "--out", str(result), "--quiet"], repeats=1)
        locate = [str(BIN / "brachycal"), "locate", str(result), str(big), "--uv", "540,360"]
        locate_s, locate_mb = run(locate, repeats=1)
        record(
            "locate 2M CSV peak memory",
            locate_mb,
            "MB",
            goal="<= 500 MB, independent of the log's length",
            met=locate_mb <= 500,
            peer="brachycal fk on the same log",
            peer_value=big_mb,
        )
        record(
            "locate 2M CSV time",
            locate_s,
            "s",
            goal="reported (no goal)",
            met=True,
            peer="brachycal fk on the same log",
            peer_value=big_s,
        )


if __name__ == "__main__":
    main()
