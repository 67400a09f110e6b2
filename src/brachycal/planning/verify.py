"""Independent check of planned poses with Pinocchio and Coal (not MuJoCo, which planned them).

Thresholds (issue 4): tip position error < 0.01 mm, needle direction error < 0.05°, tip within
0.01 mm of the image plane, tip inside the field of view, joints inside their limits by a
margin, and every checked link pair apart by at least the collision margin.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from brachycal.model.collision import ClearanceChecker
from brachycal.model.names import NEEDLE_TIP, PROBE_TIP, US_IMAGE
from brachycal.model.robot import Robot
from brachycal.planning.spec import PlanSpec
from brachycal.se3 import FloatArray, inverse, transform_points


@dataclass(frozen=True)
class Thresholds:
    position_m: float = 1e-5
    direction_rad: float = np.radians(0.05)
    plane_m: float = 1e-5
    joint_margin_rad: float = 0.05
    collision_margin_m: float = 0.010


@dataclass(frozen=True)
class PoseCheck:
    """Measured figures of one pose and the verdict.

    Attributes:
        position_error_m: needle tip to its grid point.
        direction_error_rad: needle axis to the insertion direction.
        plane_distance_m: needle tip to the image plane.
        uv_px: ``(2,)`` where the tip appears in the image.
        fov_margin_m: distance inside the field of view (negative: outside).
        joint_margin_rad: smallest distance of a joint to its limits.
        clearance_m: smallest distance between checked link pairs.
        closest_pair: the pair at that distance.
        failures: reasons (``reach``, ``direction``, ``plane``, ``fov``, ``limit``, ``collision``).
    """

    position_error_m: float
    direction_error_rad: float
    plane_distance_m: float
    uv_px: FloatArray
    fov_margin_m: float
    joint_margin_rad: float
    clearance_m: float
    closest_pair: tuple[str, str]
    failures: tuple[str, ...]

    @property
    def ok(self) -> bool:
        return not self.failures


class PoseVerifier:
    """Checks poses of a robot model (with the tool frames used for planning) against a spec."""

    def __init__(self, robot: Robot, spec: PlanSpec, checker: ClearanceChecker, thresholds: Thresholds = Thresholds()):
        self.robot, self.spec, self.checker, self.thresholds = robot, spec, checker, thresholds

    def check(self, q: ArrayLike, p_target: ArrayLike) -> PoseCheck:
        q = np.asarray(q, dtype=float)
        t = self.thresholds
        T_needle, T_image = self.robot.fk_frames([NEEDLE_TIP, US_IMAGE], q[None])[:, 0]
        position_error = float(np.linalg.norm(T_needle[:3, 3] - p_target))
        d = self.spec.insertion_dir / np.linalg.norm(self.spec.insertion_dir)
        direction_error = float(np.arccos(np.clip(T_needle[:3, 2] @ d, -1.0, 1.0)))
        p_image = transform_points(inverse(T_image), T_needle[:3, 3])
        uv = p_image[:2] / self.spec.spacing_m
        fov_margin = float(self.spec.fov.margin_to_edge(uv, self.spec.spacing_m)[0])
        joint_margin = float(np.min(np.minimum(q - self.robot.lower, self.robot.upper - q)))
        distances = self.checker.distances(q)
        k = int(np.argmin(distances))
        failures = []
        if position_error > t.position_m:
            failures.append("reach")
        if direction_error > t.direction_rad:
            failures.append("direction")
        if abs(p_image[2]) > t.plane_m:
            failures.append("plane")
        if fov_margin < 0:
            failures.append("fov")
        if joint_margin < t.joint_margin_rad:
            failures.append("limit")
        if distances[k] < t.collision_margin_m:
            failures.append("collision")
        return PoseCheck(
            position_error,
            direction_error,
            float(abs(p_image[2])),
            uv,
            fov_margin,
            joint_margin,
            float(distances[k]),
            self.checker.pairs[k],
            tuple(failures),
        )


def probe_target_error(robot: Robot, q: ArrayLike, T_base_probe: FloatArray) -> float:
    """Distance of the probe tip from its target, metres (diagnostic)."""
    return float(np.linalg.norm(robot.fk(PROBE_TIP, np.asarray(q, float))[:3, 3] - T_base_probe[:3, 3]))
