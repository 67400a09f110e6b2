"""Independent check of planned poses with Pinocchio and Coal (not MuJoCo, which planned them).

Thresholds: tip position error < 0.01 mm, needle direction error < 0.05°, tip within
0.01 mm of the image plane, tip inside the field of view, joints inside their limits by a
margin, and every checked link pair apart by at least the collision margin.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from brachycal.model.names import NEEDLE_TIP, PROBE_TIP, US_IMAGE
from brachycal.planning.spec import PlanSpec
from brachycal.se3 import FloatArray, inverse, transform_points
from brachycal.validate import check_range

if TYPE_CHECKING:  # types only: the thresholds and a pose's figures load without Pinocchio
    from brachycal.model.collision import ClearanceChecker
    from brachycal.model.robot import Robot

#: Smallest joint margin a plan may keep, radians (0.1 deg = 1.75e-3 rad). A planned pose must stay
#: inside the limits even as read back by the encoders: the joint-log and session readers accept a
#: reading at most 1e-3 rad beyond a limit (with a warning), and the encoders' noise is ~2e-5 rad
#: SD (the twin's, and well above the SDA10F's resolution), so with this floor a reading past a
#: limit would need an error of more than 80 noise SDs: it cannot happen.
MIN_JOINT_MARGIN_RAD = float(np.radians(0.1))
#: Smallest link clearance a plan may keep, metres: the collision geometry is a model (the twin's
#: kinematic error alone moves the tools 0.1-0.3 mm), so 1 mm is the least that still means apart.
MIN_COLLISION_MARGIN_M = 1e-3
#: Largest joint margin, radians (45 deg): typo guard; most SDA10F axes range over +-90..180 deg.
MAX_JOINT_MARGIN_RAD = float(np.radians(45.0))
#: Largest collision margin, metres: the probe must image the needle, so the tools are never
#: further apart than the image is deep (~0.1 m); a larger margin is a typo.
MAX_COLLISION_MARGIN_M = 0.1


@dataclass(frozen=True)
class Thresholds:
    """Acceptance thresholds of the independent check; every one finite and in range.

    Attributes:
        position_m: largest needle-tip error, metres, in (0, 1 mm]: a tolerance above 1 mm could not
            verify poses whose purpose is a sub-millimetre calibration.
        direction_rad: largest needle-axis error, radians, in (0, 5 deg].
        plane_m: largest distance of the tip from the image plane, metres, in (0, 1 mm].
        joint_margin_rad: smallest distance to a joint limit, radians, in
            [:data:`MIN_JOINT_MARGIN_RAD`, :data:`MAX_JOINT_MARGIN_RAD`].
        collision_margin_m: smallest clearance between checked link pairs, metres, in
            [:data:`MIN_COLLISION_MARGIN_M`, :data:`MAX_COLLISION_MARGIN_M`].

    Raises:
        InputError: a threshold is NaN, infinite or out of range (a NaN would switch its check off).
    """

    position_m: float = 1e-5
    direction_rad: float = np.radians(0.05)
    plane_m: float = 1e-5
    joint_margin_rad: float = 0.05
    collision_margin_m: float = 0.010

    def __post_init__(self) -> None:
        check_range(self.position_m, "position threshold", low=0.0, high=1e-3, low_open=True, unit="m")
        check_range(self.direction_rad, "direction threshold", low=0.0, high=np.radians(5.0), low_open=True, unit="rad")
        check_range(self.plane_m, "image-plane threshold", low=0.0, high=1e-3, low_open=True, unit="m")
        check_range(
            self.joint_margin_rad, "joint margin", low=MIN_JOINT_MARGIN_RAD, high=MAX_JOINT_MARGIN_RAD, unit="rad"
        )
        check_range(
            self.collision_margin_m,
            "collision margin",
            low=MIN_COLLISION_MARGIN_M,
            high=MAX_COLLISION_MARGIN_M,
            unit="m",
        )


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
        # Each test is written as "not (within the threshold)", so that a NaN figure fails it.
        failures = []
        if not position_error <= t.position_m:
            failures.append("reach")
        if not direction_error <= t.direction_rad:
            failures.append("direction")
        if not abs(p_image[2]) <= t.plane_m:
            failures.append("plane")
        if not fov_margin >= 0:
            failures.append("fov")
        if not joint_margin >= t.joint_margin_rad:
            failures.append("limit")
        if not distances[k] >= t.collision_margin_m:
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
