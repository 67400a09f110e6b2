"""Plan the calibration sample poses: grid → dual-arm IK (mink) → independent check → order."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from brachycal.errors import SolverError
from brachycal.model.collision import ClearanceChecker, collision_link_pairs
from brachycal.model.names import PROBE_TIP, US_IMAGE
from brachycal.planning import order as ordering
from brachycal.planning.dual_arm_ik import DualArmIK, IKSettings
from brachycal.planning.pose_checks import PoseCheck, PoseVerifier, Thresholds
from brachycal.planning.spec import PlanSpec
from brachycal.se3 import FloatArray
from brachycal.validate import check_range

if TYPE_CHECKING:  # the records of a plan load without the robot model (Pinocchio)
    from brachycal.model.robot import Robot


@dataclass(frozen=True)
class GridPoint:
    name: str
    index: np.ndarray  # (3,) ints: lateral, depth, normal
    p_base: FloatArray  # (3,) metres
    uv_px: FloatArray  # (2,) expected pixel
    normal_offset_m: float


@dataclass(frozen=True)
class PlannedPose:
    point: GridPoint
    q: FloatArray  # (nq,) radians, model order
    check: PoseCheck
    iterations: int


@dataclass(frozen=True)
class Infeasible:
    """A grid point without a verified pose: ``reasons`` from the check (``reach``, ``direction``,
    ``plane``, ``fov``, ``limit``, ``collision``) or ``solver`` (the IK's QP had no solution), and a
    one-line ``detail``."""

    point: GridPoint
    reasons: tuple[str, ...]
    detail: str


@dataclass(frozen=True, repr=False)
class Plan:
    """Feasible poses in visiting order, the infeasible points with reasons, and timings.

    Attributes:
        poses: in the optimised order (nearest neighbour + 2-opt from :attr:`start_q`).
        infeasible: grid points without a verified pose.
        motion_time_s: ``{"raster", "serpentine", "optimised"}`` → seconds from ``start_q``.
        speed_scale: fraction of the vendor's velocity limits used for the motion times.
        solve_time_s: wall time of IK and checks.
        start_q: ``(nq,)`` where the robot starts, radians: the rig's ready stance.
    """

    spec: PlanSpec
    poses: list[PlannedPose]
    infeasible: list[Infeasible]
    motion_time_s: dict[str, float]
    speed_scale: float
    solve_time_s: float
    start_q: FloatArray

    @property
    def min_clearance_m(self) -> float:
        return min((p.check.clearance_m for p in self.poses), default=float("nan"))

    def __repr__(self) -> str:
        motion = self.motion_time_s.get("optimised", float("nan"))
        return (
            f"Plan: {len(self.poses)} feasible sample poses, {len(self.infeasible)} infeasible; "
            f"optimised motion {motion:.0f} s at {self.speed_scale:g} of the velocity limits; "
            f"least clearance {self.min_clearance_m * 1e3:.1f} mm"
        )


def grid_points(spec: PlanSpec) -> list[GridPoint]:
    index, p_base, uv, normal = spec.grid()
    if spec.offsets_m is None:
        names = [f"g{i}{j}{k}" for i, j, k in index]
    else:
        names = [f"p{n + 1:03d}" for n in range(len(index))]
    return [GridPoint(names[n], index[n], p_base[n], uv[n], float(normal[n])) for n in range(len(index))]


def _reasons_for_failed_ik(check: PoseCheck, settings: IKSettings) -> tuple[str, ...]:
    """Why the IK stopped short: a constraint holding it back, else the target is out of reach."""
    reasons = []
    if check.clearance_m < settings.collision_margin_m + 1e-3:
        reasons.append("collision")
    if check.joint_margin_rad < settings.joint_margin_rad + 1e-3:
        reasons.append("limit")
    return tuple(reasons) or ("reach",)


def plan_poses(
    robot: Robot,
    spec: PlanSpec,
    *,
    settings: IKSettings = IKSettings(),
    thresholds: Thresholds = Thresholds(),
    speed_scale: float = 1.0,
    progress: Callable[[int], None] | None = None,
) -> Plan:
    """Plan one pose per grid point.

    Args:
        robot: the model with the tool frames to plan with (nominal, or a calibration's); its rig
            (``robot.rig``) gives the ready stance (start and posture target) and the collision pairs.
        spec: the grid and imaging geometry.
        settings: IK settings (margins a little larger than the check's thresholds).
        thresholds: the independent check's acceptance thresholds.
        speed_scale: fraction of the vendor's velocity limits for the motion-time estimate.
        progress: called with 1 after each grid point.
    """
    check_range(speed_scale, "speed scale", low=0.0, high=1.0, low_open=True)
    start = time.perf_counter()
    ik = DualArmIK(robot, settings)
    verifier = PoseVerifier(robot, spec, ClearanceChecker(robot, collision_link_pairs(robot)), thresholds)
    # The image on the probe tip, by forward kinematics (both hang on the left flange, so any
    # configuration gives it): reading the URDF's rpy would load SciPy's rotations for one matrix.
    ready = robot.rig.ready
    T_Ptip_I = robot.transform(PROBE_TIP, US_IMAGE, ready)
    points = grid_points(spec)
    solve_order = ordering.serpentine(np.array([p.index for p in points]))
    q = ready.copy()
    feasible: list[PlannedPose] = []
    infeasible: list[Infeasible] = []
    for n in solve_order:
        point = points[n]
        fov_margin = float(spec.fov.margin_to_edge(point.uv_px, spec.spacing_m)[0])
        if fov_margin < spec.fov_margin_m:
            infeasible.append(
                Infeasible(
                    point,
                    ("fov",),
                    f"pixel ({point.uv_px[0]:.0f}, {point.uv_px[1]:.0f}) is "
                    f"{-fov_margin * 1e3:.1f} mm outside the field of view's margin",
                )
            )
        else:
            try:
                outcome = ik.solve(q, spec.needle_pose(point.p_base), spec.probe_pose(point.normal_offset_m, T_Ptip_I))
            except SolverError as exc:
                # The QP of one step had no solution: this point has no pose and the plan goes on from
                # the last good one (solver failures only; bad input propagates).
                infeasible.append(Infeasible(point, ("solver",), str(exc)))
            else:
                check = verifier.check(outcome.q, point.p_base)
                if outcome.converged and check.ok:
                    feasible.append(PlannedPose(point, outcome.q, check, outcome.iterations))
                    q = outcome.q
                else:
                    reasons = check.failures if outcome.converged else _reasons_for_failed_ik(check, settings)
                    infeasible.append(Infeasible(point, reasons, _detail(check, outcome.position_error_m)))
        if progress is not None:
            progress(1)
    motion, visit = _order(feasible, robot, ready, speed_scale)
    elapsed = time.perf_counter() - start
    return Plan(spec, [feasible[k] for k in visit], infeasible, motion, speed_scale, elapsed, ready)


def _detail(check: PoseCheck, ik_error_m: float) -> str:
    return (
        f"tool error {ik_error_m * 1e3:.3f} mm, clearance {check.clearance_m * 1e3:.1f} mm "
        f"({check.closest_pair[0]}/{check.closest_pair[1]}), joint margin {np.degrees(check.joint_margin_rad):.1f}°"
    )


def _order(
    feasible: list[PlannedPose], robot: Robot, start_q: FloatArray, speed_scale: float
) -> tuple[dict[str, float], np.ndarray]:
    if not feasible:
        return {"raster": 0.0, "serpentine": 0.0, "optimised": 0.0}, np.zeros(0, dtype=int)
    Q = np.array([start_q, *(p.q for p in feasible)])
    times = ordering.move_times(Q, robot.velocity_limit, speed_scale)
    index = np.array([p.point.index for p in feasible])
    orders = {
        "raster": ordering.raster(index),
        "serpentine": ordering.serpentine(index),
        "optimised": ordering.nearest_neighbour_two_opt(times, start=0) - 1,
    }
    motion = {name: ordering.path_time(order + 1, times, start=0) for name, order in orders.items()}
    return motion, orders["optimised"]
