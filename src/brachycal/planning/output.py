"""Plan files: the pose table for the robot, and the list of infeasible points.

``plan.csv``: one row per pose in visiting order — ``order,point,i,j,k`` (grid indices along the
image's lateral, depth and normal axes), ``x,y,z`` (needle-tip target in the robot's base frame, metres),
``u_px,v_px`` (where the tip should appear in the image), ``move_s`` (motion time from the
previous pose; the first from the ready stance), ``clearance_mm`` (smallest checked link
distance), then the joints in the controller's order (``robot.rig.controller_joint_names``; the
SDA10F's 15) in radians, then the same in degrees (``<joint>_deg``) for the teach pendant.

``<plan>_infeasible.csv``: ``point,i,j,k,x,y,z,u_px,v_px,reasons,detail`` for every grid point
without a verified pose; reasons are ``fov``, ``reach``, ``collision``, ``limit``, ``direction``,
``plane``.
"""

from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np

from brachycal.io import atomic_open
from brachycal.model.robot import Robot
from brachycal.planning import order as ordering
from brachycal.planning.plan import Plan


def infeasible_path(plan_path: str | os.PathLike[str]) -> Path:
    path = Path(plan_path)
    return path.with_name(path.stem + "_infeasible.csv")


def write_plan(plan: Plan, robot: Robot, path: str | os.PathLike[str], *, force: bool = False) -> Path:
    """Write the pose table (atomically), the joints in the robot's controller order."""
    controller = robot.rig.controller_joint_names
    columns = [robot.joint_names.index(name) for name in controller]
    Q = np.array([plan.start_q, *(pose.q for pose in plan.poses)])
    times = ordering.move_times(Q, robot.velocity_limit, plan.speed_scale)
    header = [
        "order",
        "point",
        "i",
        "j",
        "k",
        "x",
        "y",
        "z",
        "u_px",
        "v_px",
        "move_s",
        "clearance_mm",
        *controller,
        *(f"{name}_deg" for name in controller),
    ]
    with atomic_open(path, force=force) as f:
        f.write(",".join(header) + "\n")
        for n, pose in enumerate(plan.poses, start=1):
            p, q = pose.point, pose.q[columns]
            fields = [
                str(n),
                p.name,
                *map(str, p.index),
                *(f"{x:.9f}" for x in p.p_base),
                f"{p.uv_px[0]:.3f}",
                f"{p.uv_px[1]:.3f}",
                f"{times[n - 1, n]:.3f}",
                f"{pose.check.clearance_m * 1e3:.1f}",
                *(f"{x:.9f}" for x in q),
                *(f"{x:.4f}" for x in np.degrees(q)),
            ]
            f.write(",".join(fields) + "\n")
    return Path(path)


def write_infeasible(plan: Plan, path: str | os.PathLike[str], *, force: bool = False) -> Path:
    """Write the infeasible points with their reasons (atomically)."""
    with atomic_open(path, force=force) as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(["point", "i", "j", "k", "x", "y", "z", "u_px", "v_px", "reasons", "detail"])
        for item in plan.infeasible:
            p = item.point
            writer.writerow(
                [
                    p.name,
                    *p.index.tolist(),
                    *(f"{x:.9f}" for x in p.p_base),
                    f"{p.uv_px[0]:.3f}",
                    f"{p.uv_px[1]:.3f}",
                    "+".join(item.reasons),
                    item.detail,
                ]
            )
    return Path(path)
