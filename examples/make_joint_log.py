"""Regenerate ``examples/joint_log.csv``, the bundled example joint log.

Run from the repository root: ``python examples/make_joint_log.py``. Deterministic.

Ten seconds at 50 Hz of the SDA10F moving from its home pose (all zeros) to a calibration-like
pose: the probe held horizontally, pointing forward (+x of base_link), its image plane vertical;
the needle 35° off the probe axis, its nominal tip in the image plane 60 mm above the probe axis
and 45 mm deep. Poses are solved with brachycal's damped least-squares IK (an example-making
tool, not the planner). Motion follows a smooth quintic time law; the torso stays at 0.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from brachycal.model import Robot
from brachycal.model.ik import solve_ik
from brachycal.se3 import make_transform, transform_points

SPACING_M = 0.19e-3


def main() -> None:
    robot = Robot.load()
    left = list(range(1, 8))
    right = list(range(8, 15))
    # Probe: z (shaft) along +x of base, x (image lateral) along +z of base.
    R_base_probe = np.column_stack([[0, 0, 1], [0, -1, 0], [1, 0, 0]]).astype(float)
    T_base_probe = make_transform(R_base_probe, [0.80, 0.10, 1.00])
    seed = np.zeros(robot.nq)
    seed[left] = [0.3, -1.0, 0.0, -1.3, 0.0, -0.6, 0.0]
    seed[right] = [0.3, -1.0, 0.0, -1.3, 0.0, -0.6, 0.0]
    q_goal = solve_ik(robot, "probe_tip", T_base_probe, seed, left, margin=0.05, restarts=50, seed=7)

    T_base_image = robot.fk("us_image", q_goal)
    u, v = 540 + 60e-3 / SPACING_M, 45e-3 / SPACING_M
    p_base_target = transform_points(T_base_image, [u * SPACING_M, v * SPACING_M, 0.0])
    # Needle inclined 35 degrees towards the robot's right, so the two wrists stay apart.
    yaw = np.radians(35.0)
    R_yaw = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
    T_base_needle = make_transform(R_yaw @ R_base_probe, p_base_target)
    q_goal = solve_ik(robot, "needle_tip", T_base_needle, q_goal, right, margin=0.05, restarts=50, seed=7)

    time = np.linspace(0.0, 10.0, 501)
    s = time / time[-1]
    blend = 10 * s**3 - 15 * s**4 + 6 * s**5
    Q = blend[:, None] * q_goal[None, :]
    header = "time," + ",".join(robot.joint_names)
    rows = [f"{t:.2f}," + ",".join(f"{x:.9f}" for x in q) for t, q in zip(time, Q, strict=True)]
    out = Path(__file__).with_name("joint_log.csv")
    out.write_text(header + "\n" + "\n".join(rows) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
