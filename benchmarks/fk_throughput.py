"""Forward-kinematics throughput: two tool frames from a 100,000-sample joint log.

Run: ``make bench`` (or ``.venv/bin/python benchmarks/fk_throughput.py [N]``). Prints samples per
second and peak memory for brachycal's batch path and, in the same run, for a plain per-sample
Pinocchio loop (``forwardKinematics`` + ``updateFramePlacement`` per frame), then the
end-to-end time of ``brachycal fk`` on a CSV log of the same size (read, validate, FK, write).
Figures are the best of three repeats.
"""

from __future__ import annotations

import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pinocchio as pin
from timing import best_of

from brachycal.cli.main import main as cli
from brachycal.model import Robot

FRAMES = ["needle_tip", "probe_tip"]


def pinocchio_loop(robot: Robot, Q: np.ndarray) -> np.ndarray:
    model, data = robot.model, robot.model.createData()
    ids = [model.getFrameId(f) for f in FRAMES]
    out = np.empty((len(ids), len(Q), 4, 4))
    for i, q in enumerate(Q):
        pin.forwardKinematics(model, data, q)
        for k, fid in enumerate(ids):
            out[k, i] = pin.updateFramePlacement(model, data, fid).homogeneous
    return out


def main(n: int = 100_000) -> None:
    robot = Robot.load()
    rng = np.random.default_rng(0)
    Q = rng.uniform(robot.lower, robot.upper, size=(n, robot.nq))

    batch_s = best_of(3, lambda: robot.fk_frames(FRAMES, Q))
    tracemalloc.start()
    poses = robot.fk_frames(FRAMES, Q)
    batch_peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()

    loop_s = best_of(3, lambda: pinocchio_loop(robot, Q))
    tracemalloc.start()
    reference = pinocchio_loop(robot, Q)
    loop_peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    agreement = float(np.abs(poses - reference).max())

    print(f"forward kinematics of {len(FRAMES)} frames ({', '.join(FRAMES)}), {n:,} samples, 15 axes")
    print(
        f"  brachycal batch path   {n / batch_s:>12,.0f} samples/s   {batch_s * 1e3:8.1f} ms   "
        f"peak {batch_peak / 2**20:6.1f} MiB"
    )
    print(
        f"  Pinocchio per-sample   {n / loop_s:>12,.0f} samples/s   {loop_s * 1e3:8.1f} ms   "
        f"peak {loop_peak / 2**20:6.1f} MiB"
    )
    print(f"  speed-up {loop_s / batch_s:.2f}x; largest difference {agreement:.1e} m")
    print(f"  (the output itself, {len(FRAMES)} x {n:,} 4x4 poses, is {poses.nbytes / 2**20:.1f} MiB)")

    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "log.csv"
        t = np.arange(n) * 0.001
        body = "\n".join(f"{ti:.3f}," + ",".join(f"{x:.9f}" for x in q) for ti, q in zip(t, Q, strict=True))
        log.write_text("time," + ",".join(robot.joint_names) + "\n" + body + "\n")
        out = Path(tmp) / "poses.csv"
        start = time.perf_counter()
        cli(["fk", str(log), "--frames", ",".join(FRAMES), "--out", str(out), "--quiet", "--force"])
        cli_s = time.perf_counter() - start
    print(f"  brachycal fk end to end (read CSV, validate, FK, write {2 * n:,} rows): {cli_s:.2f} s")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 100_000)
