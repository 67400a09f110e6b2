"""Planning speed: the default 64-pose plan (4 × 4 × 4 grid in a 40 mm cube).

Run: ``.venv/bin/python benchmarks/plan_speed.py``. Two figures:

- end to end, what a user waits for: ``brachycal plan --out plan.csv`` in a new process (start-up,
  imports, robot, IK, checks, ordering, CSV and figure), best of 3; recorded in
  ``benchmarks/results.json`` beside the peer :data:`BEFORE_S` (the same command before issue 13),
  goal :data:`GOAL_S`;
- the planner alone, :func:`brachycal.planning.plan_poses` in this process (set-up, mink IK,
  Pinocchio checks, ordering), best of 3, with its IK iterations, motion time and clearance.

On two cores the command's second process draws the figure: it loads matplotlib and, if the plan
has not come yet, draws a stand-in figure to warm matplotlib's caches, so that the plan's figure
(the same pixels) takes ~0.2 s after the plan instead of ~0.45 s.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np
from timing import best_of, best_wall, brachycal_command, record

from brachycal.model import Robot
from brachycal.planning import PlanSpec, plan_poses

#: ``brachycal plan --out plan.csv`` end to end before issue 13 (everything imported up front), seconds,
#: as measured on this 2-core machine kind (issue 13's table).
BEFORE_S = 3.3
#: Issue 13's goal for the same command, seconds.
GOAL_S = 1.5


def end_to_end(repeats: int = 3) -> float:
    """Best wall time of ``brachycal plan`` with the default grid, in a new process, seconds."""
    with tempfile.TemporaryDirectory() as tmp:
        argv = ["plan", "--out", str(Path(tmp) / "plan.csv"), "--force", "--quiet"]
        return best_wall([*brachycal_command(), *argv], repeats)


def main() -> None:
    value = end_to_end()
    record(
        "plan: brachycal plan (64 poses) end to end",
        value,
        "s",
        goal=f"<= {GOAL_S} s",
        met=value <= GOAL_S,
        peer="before issue 13",
        peer_value=BEFORE_S,
    )
    robot = Robot.load()
    spec = PlanSpec()
    total = best_of(3, lambda: plan_poses(robot, spec))
    start = time.perf_counter()
    plan = plan_poses(robot, spec)
    once = time.perf_counter() - start
    n = len(plan.poses) + len(plan.infeasible)
    iterations = np.array([pose.iterations for pose in plan.poses])
    m = plan.motion_time_s
    print(f"default plan: {len(plan.poses)} of {n} poses feasible")
    print(f"  planning time {total:.2f} s (best of 3; {once:.2f} s this run), {total / n * 1e3:.1f} ms per pose")
    print(f"  IK iterations per pose: median {np.median(iterations):.0f}, max {iterations.max()}")
    print(
        f"  motion at vendor speed: optimised {m['optimised']:.2f} s, serpentine {m['serpentine']:.2f} s, "
        f"raster {m['raster']:.2f} s"
    )
    print(f"  smallest link clearance {plan.min_clearance_m * 1e3:.1f} mm")


if __name__ == "__main__":
    main()
