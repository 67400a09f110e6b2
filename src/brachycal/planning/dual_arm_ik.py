"""Dual-arm inverse kinematics with mink on the MuJoCo model of the project's URDF.

One differential-IK problem moves all 15 axes at once: the torso is shared by both arms and
solved jointly. Tasks: the needle tip on its target with the needle along the insertion
direction (roll about the needle left free), the probe tip on its target pose, and a light
posture task that keeps the arms near a comfortable stance. Limits: joint limits with a margin,
joint velocity limits (so each iteration, and hence the path between successive poses, respects
the vendor's speeds), and collision avoidance between the link pairs of
:func:`brachycal.model.collision.collision_link_pairs` with a safety margin.
"""

from __future__ import annotations

from dataclasses import dataclass

import mink
import numpy as np
from numpy.typing import ArrayLike

from brachycal.model.collision import collision_link_pairs
from brachycal.model.names import NEEDLE_TIP, PROBE_TIP
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray

#: A comfortable stance for the calibration (both arms bent forward), radians, model order.
READY = np.array([0.0, 0.3, -1.0, 0.0, -1.3, 0.0, -0.6, 0.0, 0.3, -1.0, 0.0, -1.3, 0.0, -0.6, 0.0])


@dataclass(frozen=True)
class IKSettings:
    """Solver settings.

    Attributes:
        collision_margin_m: keep every checked link pair at least this far apart.
        joint_margin_rad: keep joints this far inside their limits.
        dt: integration step of the differential IK, seconds.
        max_iterations: per target.
        position_tol_m: stop when the tips are this close to their targets ...
        angle_tol_rad: ... and the orientations this close.
        posture_cost: weight of the comfortable-stance task (small: a tie-breaker).
        finish_radius_m: once both tips are this close, the posture task is dropped so the
            tools can reach their targets exactly.
    """

    collision_margin_m: float = 0.012
    joint_margin_rad: float = 0.06
    dt: float = 0.05
    max_iterations: int = 400
    position_tol_m: float = 1e-7
    angle_tol_rad: float = 1e-7
    posture_cost: float = 1e-3
    finish_radius_m: float = 5e-3


@dataclass(frozen=True)
class IKOutcome:
    q: FloatArray
    converged: bool
    iterations: int
    position_error_m: float
    angle_error_rad: float


def _se3(T: FloatArray) -> mink.SE3:
    return mink.SE3.from_matrix(np.asarray(T, dtype=float))


class DualArmIK:
    """Reusable solver for one robot model (tool frames included) and settings."""

    def __init__(self, robot: Robot, settings: IKSettings = IKSettings()) -> None:
        self.robot = robot
        self.settings = settings
        model = robot.mujoco_model()
        self.model = model
        self.configuration = mink.Configuration(model)
        self.needle_task = mink.FrameTask(NEEDLE_TIP, "body", position_cost=1.0, orientation_cost=[1.0, 1.0, 0.0])
        self.probe_task = mink.FrameTask(PROBE_TIP, "body", position_cost=1.0, orientation_cost=1.0)
        self.posture_task = mink.PostureTask(model, cost=settings.posture_cost)
        self.posture_task.set_target(READY)
        geom_of_body = {model.body(model.geom_bodyid[g]).name: g for g in range(model.ngeom)}
        pairs = [([geom_of_body[a]], [geom_of_body[b]]) for a, b in collision_link_pairs(robot)]
        velocities = {name: float(v) for name, v in zip(robot.joint_names, robot.velocity_limit, strict=True)}
        self.limits = [
            mink.ConfigurationLimit(model, min_distance_from_limits=settings.joint_margin_rad),
            mink.VelocityLimit(model, velocities),
            mink.CollisionAvoidanceLimit(
                model,
                pairs,
                minimum_distance_from_collisions=settings.collision_margin_m,
                collision_detection_distance=settings.collision_margin_m + 0.05,
            ),
        ]

    def solve(self, q_start: ArrayLike, T_base_needle: FloatArray, T_base_probe: FloatArray) -> IKOutcome:
        """Move from ``q_start`` until both tools reach their targets (or the iterations run out)."""
        s = self.settings
        self.configuration.update(np.asarray(q_start, dtype=float).copy())
        self.needle_task.set_target(_se3(T_base_needle))
        self.probe_task.set_target(_se3(T_base_probe))
        # The posture task is soft: kept on, it would leave the tools a little off target (its
        # pull trades against theirs). It shapes the approach, then steps aside for the finish.
        tasks = [self.needle_task, self.probe_task, self.posture_task]
        pos_err = ang_err = np.inf
        for iteration in range(1, s.max_iterations + 1):
            if pos_err < s.finish_radius_m and len(tasks) == 3:
                tasks = tasks[:2]
            velocity = mink.solve_ik(self.configuration, tasks, s.dt, "daqp", damping=1e-9, limits=self.limits)
            self.configuration.integrate_inplace(velocity, s.dt)
            e_needle = self.needle_task.compute_error(self.configuration)
            e_probe = self.probe_task.compute_error(self.configuration)
            pos_err = max(np.linalg.norm(e_needle[:3]), np.linalg.norm(e_probe[:3]))
            ang_err = max(np.linalg.norm(e_needle[3:5]), np.linalg.norm(e_probe[3:]))
            if pos_err < s.position_tol_m and ang_err < s.angle_tol_rad:
                return IKOutcome(self.configuration.q.copy(), True, iteration, pos_err, ang_err)
        return IKOutcome(self.configuration.q.copy(), False, s.max_iterations, pos_err, ang_err)
