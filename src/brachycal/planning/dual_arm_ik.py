"""Dual-arm inverse kinematics with mink on the MuJoCo model of the robot's URDF.

One differential-IK problem moves every axis at once (the SDA10F's 15): joints both arms share (the
SDA10F's torso) are solved jointly. Tasks: the needle tip on its target with the needle along the
insertion direction (roll about the needle left free), the probe tip on its target pose, and a light
posture task that keeps the arms near the rig's ready stance (``robot.rig.ready``). Limits: joint limits with a margin,
joint velocity limits (so each iteration, and hence the path between successive poses, respects
the vendor's speeds), and collision avoidance between the link pairs of
:func:`brachycal.model.collision.collision_link_pairs` with a safety margin.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from brachycal.errors import InputError, SolverError
from brachycal.model.collision import collision_link_pairs
from brachycal.model.names import NEEDLE_TIP, PROBE_TIP
from brachycal.se3 import FloatArray
from brachycal.validate import check_finite, check_int, check_range, check_transform

# mink (with MuJoCo and the QP solvers) and the robot model are imported by the solver itself: the
# settings and a plan's records (pickled to the process that draws a plan) need neither.
if TYPE_CHECKING:
    import mink

    from brachycal.model.robot import Robot

#: The QP solver of each differential-IK step (qpsolvers' name).
QP_SOLVER = "daqp"


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

    Every setting must be finite and in range: margins in [0, 0.15 m] and [0, 50 deg] (a little
    above the largest :class:`~brachycal.planning.pose_checks.Thresholds`, since the IK keeps more
    than the check asks; the thresholds set the floors a plan must keep), ``dt`` in (0, 1] s,
    ``max_iterations`` in [1, 100000], tolerances in (0, 1 mm] and (0, 0.1 rad], ``posture_cost``
    in [0, 1], ``finish_radius_m`` in [0, 0.1 m].

    Raises:
        InputError: a setting is NaN, infinite or out of range.
    """

    collision_margin_m: float = 0.012
    joint_margin_rad: float = 0.06
    dt: float = 0.05
    max_iterations: int = 400
    position_tol_m: float = 1e-7
    angle_tol_rad: float = 1e-7
    posture_cost: float = 1e-3
    finish_radius_m: float = 5e-3

    def __post_init__(self) -> None:
        check_range(self.collision_margin_m, "IK collision margin", low=0.0, high=0.15, unit="m")
        check_range(self.joint_margin_rad, "IK joint margin", low=0.0, high=float(np.radians(50.0)), unit="rad")
        check_range(self.dt, "IK time step", low=0.0, high=1.0, low_open=True, unit="s")
        check_int(self.max_iterations, "IK iterations", low=1, high=100_000)
        check_range(self.position_tol_m, "IK position tolerance", low=0.0, high=1e-3, low_open=True, unit="m")
        check_range(self.angle_tol_rad, "IK angle tolerance", low=0.0, high=0.1, low_open=True, unit="rad")
        # The posture task is a tie-breaker next to the tool tasks' unit weights.
        check_range(self.posture_cost, "IK posture cost", low=0.0, high=1.0)
        check_range(self.finish_radius_m, "IK finish radius", low=0.0, high=0.1, unit="m")


@dataclass(frozen=True)
class IKOutcome:
    q: FloatArray
    converged: bool
    iterations: int
    position_error_m: float
    angle_error_rad: float


def _se3(T: FloatArray) -> mink.SE3:
    import mink  # lazy: start-up (mink)

    return mink.SE3.from_matrix(np.asarray(T, dtype=float))


class DualArmIK:
    """Reusable solver for one robot model (tool frames included) and settings.

    MuJoCo may order the joints otherwise than Pinocchio (Baxter: right arm first); configurations
    cross between the two by joint name.

    Raises:
        InputError: MuJoCo's configuration of the robot is not brachycal's (a floating or planar
            joint, or a mimic joint MuJoCo moves on its own), so a configuration could not be
            handed from one to the other unchanged; or the robot has no rig.
    """

    def __init__(self, robot: Robot, settings: IKSettings = IKSettings()) -> None:
        import mink  # lazy: start-up (mink)
        import mujoco  # lazy: start-up (mujoco)

        self.robot = robot
        self.settings = settings
        rig = robot.rig
        model = robot.mujoco_model()
        mujoco_joints = tuple(model.joint(j).name for j in range(model.njnt))
        one_axis_types = {int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)}
        one_axis = all(int(model.jnt_type[j]) in one_axis_types for j in range(model.njnt))
        if model.nq != robot.nq or sorted(mujoco_joints) != sorted(robot.joint_names) or not one_axis:
            raise InputError(
                f"dual-arm IK needs MuJoCo's joints to be the robot's coordinates ({robot.nq}: "
                f"{', '.join(robot.joint_names)}); MuJoCo reads {model.nq} coordinates of {', '.join(mujoco_joints)} "
                "(planning supports revolute, prismatic and continuous joints)",
                file=robot.source,
            )
        self.model = model
        #: MuJoCo's coordinate of each of the robot's: ``q_mujoco[self._mujoco_index] = q``.
        self._mujoco_index = np.array([int(model.joint(name).qposadr[0]) for name in robot.joint_names])
        self.configuration = mink.Configuration(model)
        self.needle_task = mink.FrameTask(NEEDLE_TIP, "body", position_cost=1.0, orientation_cost=[1.0, 1.0, 0.0])
        self.probe_task = mink.FrameTask(PROBE_TIP, "body", position_cost=1.0, orientation_cost=1.0)
        self.posture_task = mink.PostureTask(model, cost=settings.posture_cost)
        self.posture_task.set_target(self._to_mujoco(rig.ready))
        # A link may carry several shapes (Baxter's head: two spheres): the pair keeps all of them apart.
        geoms_of_body: dict[str, list[int]] = {}
        for g in range(model.ngeom):
            geoms_of_body.setdefault(model.body(model.geom_bodyid[g]).name, []).append(g)
        pairs = [(geoms_of_body[a], geoms_of_body[b]) for a, b in collision_link_pairs(robot)]
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
        """Move from ``q_start`` until both tools reach their targets (or the iterations run out).

        Args:
            q_start: ``(nq,)`` start configuration, radians, model order.
            T_base_needle: ``(4, 4)`` target of the needle tip in the robot's base (``robot.rig.base``,
                metres).
            T_base_probe: ``(4, 4)`` target of the probe tip, likewise.

        Returns:
            The last configuration, whether it converged, and the remaining errors; running out of
            iterations is an outcome (``converged=False``), not an error.

        Raises:
            InputError: a start or target that is not finite, or not a rigid transform.
            SolverError: the QP of an iteration has no solution (its constraints contradict each
                other, e.g. a start already inside the collision margin); the message names the
                iteration and the targets.
        """
        s = self.settings
        q = check_finite(q_start, "IK start configuration")
        if q.shape != (self.robot.nq,):
            raise InputError(f"IK start configuration must have {self.robot.nq} joints, got shape {q.shape}")
        T_base_needle = check_transform(T_base_needle, "needle target")
        T_base_probe = check_transform(T_base_probe, "probe target")
        self.configuration.update(self._to_mujoco(q))
        self.needle_task.set_target(_se3(T_base_needle))
        self.probe_task.set_target(_se3(T_base_probe))
        # The posture task is soft: kept on, it would leave the tools a little off target (its
        # pull trades against theirs). It shapes the approach, then steps aside for the finish.
        tasks = [self.needle_task, self.probe_task, self.posture_task]
        pos_err = ang_err = np.inf
        for iteration in range(1, s.max_iterations + 1):
            if pos_err < s.finish_radius_m and len(tasks) == 3:
                tasks = tasks[:2]
            velocity = self._step(tasks, iteration, T_base_needle, T_base_probe)
            self.configuration.integrate_inplace(velocity, s.dt)
            e_needle = self.needle_task.compute_error(self.configuration)
            e_probe = self.probe_task.compute_error(self.configuration)
            pos_err = float(max(np.linalg.norm(e_needle[:3]), np.linalg.norm(e_probe[:3])))
            ang_err = float(max(np.linalg.norm(e_needle[3:5]), np.linalg.norm(e_probe[3:])))
            if pos_err < s.position_tol_m and ang_err < s.angle_tol_rad:
                return IKOutcome(self._from_mujoco(self.configuration.q), True, iteration, pos_err, ang_err)
        return IKOutcome(self._from_mujoco(self.configuration.q), False, s.max_iterations, pos_err, ang_err)

    def _to_mujoco(self, q: FloatArray) -> FloatArray:
        """``(nq,)`` MuJoCo configuration of a robot configuration ``(nq,)`` (a new array)."""
        out = np.empty(len(self._mujoco_index))
        out[self._mujoco_index] = q
        return out

    def _from_mujoco(self, q_mujoco: FloatArray) -> FloatArray:
        """``(nq,)`` robot configuration of a MuJoCo configuration (a new array)."""
        return np.asarray(q_mujoco, dtype=float)[self._mujoco_index].copy()

    def _step(self, tasks: list, iteration: int, T_base_needle: FloatArray, T_base_probe: FloatArray) -> FloatArray:
        """One differential-IK velocity, ``(nv,)`` rad/s; a QP without solution becomes :class:`SolverError`."""
        import mink  # lazy: start-up (mink)
        import qpsolvers  # lazy: start-up (qpsolvers)

        try:
            velocity = mink.solve_ik(
                self.configuration, tasks, self.settings.dt, QP_SOLVER, damping=1e-9, limits=self.limits
            )
        # mink raises NoSolutionFound when the QP solver reports failure; older mink versions assert on a
        # missing solution instead (AssertionError), and qpsolvers raises its own errors on a bad problem.
        except (mink.NoSolutionFound, qpsolvers.exceptions.QPError, AssertionError) as exc:
            raise SolverError(
                f"dual-arm IK: the QP solver {QP_SOLVER} found no joint velocity at iteration {iteration} "
                f"moving {NEEDLE_TIP} to {_where(T_base_needle)} m and {PROBE_TIP} to {_where(T_base_probe)} m "
                f"in {self.robot.rig.base} (joint limits with a {self.settings.joint_margin_rad:g} rad margin, "
                f"velocity limits and a {self.settings.collision_margin_m * 1e3:g} mm collision margin cannot all hold"
                f"{self._outside_limits()}): {exc or type(exc).__name__}"
            ) from exc
        if velocity is None or not np.all(np.isfinite(velocity)):
            raise SolverError(
                f"dual-arm IK: the QP solver {QP_SOLVER} returned no finite joint velocity at iteration {iteration} "
                f"moving {NEEDLE_TIP} to {_where(T_base_needle)} m and {PROBE_TIP} to {_where(T_base_probe)} m"
            )
        return velocity

    def _outside_limits(self) -> str:
        """``"; outside its limits: <joints>"`` for the joints of the current configuration beyond their limits."""
        q = self._from_mujoco(self.configuration.q)
        names = [
            n
            for n, v, lo, hi in zip(self.robot.joint_names, q, self.robot.lower, self.robot.upper, strict=True)
            if not lo <= v <= hi
        ]
        return f"; outside its limits: {', '.join(names)}" if names else ""


def _where(T: FloatArray) -> list[float]:
    """The translation of a target, metres, rounded to 0.1 mm for a message."""
    return np.round(np.asarray(T)[:3, 3], 4).tolist()
