"""Planning speed: the default 64-pose plan (4 × 4 × 4 grid in a 40 mm cube).

Run: ``.venv/bin/python benchmarks/plan_speed.py``. Prints the best of three runs of
:func:`brachycal.planning.plan_poses` (set-up, mink IK, Pinocchio checks, ordering), the time
per pose, IK iterations, and the plan's motion time and clearance. Aim: under 5 s on 2 cores.
"""

from __future__ import annotations

import time

import numpy as np
from timing import best_of

from brachycal.model import Robot
from brachycal.planning import PlanSpec, plan_poses


def main() -> None:
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
