"""The poses of a check before each procedure (``brachycal plan check``): a few of the grid's.

Criterion: greedy Bayesian D-optimal design. Each candidate pose ``i`` of the full plan (the
paper's 4 × 4 × 4 grid) has the sensitivity ``J_i`` (3 × 11) of its check residual — the needle tip
where the image shows it, against where the needle arm puts it (:mod:`brachycal.calibration.verify.check`)
— to each part of the chain: the needle tip (3, per mm), the probe mount with its image (6, per
mm and per degree; an image-transform change has the same effect on samples) and the image scale
(2, per %). Poses are added one at a time, each the one that most increases
``log det(I + Σ_i J_iᵀ J_i / σ²)`` (σ: 0.19 mm per coordinate, one pixel of the paper's scanner; the
identity is a prior of 1 mm / 1° / 1 % on every parameter, so the first poses already count). The
picked poses are then ordered to shorten the robot's motion, as the full plan is.

The check's robot time is stated at the paper's pace,
:data:`~brachycal.planning.robot_time.SECONDS_PER_SAMPLE` per sample
(image, annotation), plus the motion between poses at the given speed, plus
:data:`SECONDS_PER_TOUCH` for each optional single touch of a tool on ``rtip1`` (:data:`TOUCH_CHOICES`:
both the needle's and the probe's, the probe's alone, or none).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from brachycal.errors import InputError
from brachycal.model.names import NEEDLE_TIP, PROBE_TIP, US_IMAGE
from brachycal.planning import order as ordering
from brachycal.planning.robot_time import SECONDS_PER_SAMPLE
from brachycal.se3 import FloatArray
from brachycal.validate import check_int

if TYPE_CHECKING:
    from brachycal.calibration.result import Calibration
    from brachycal.model.robot import Robot
    from brachycal.planning.plan import Plan

#: Robot time per single touch of a tool on a reference tip, seconds: jogging a tip onto a tip by
#: hand takes longer than an image (an assumption, stated; the paper gives no figure).
SECONDS_PER_TOUCH = 30.0
#: The default check: 8 samples and the probe's touch, 1.9 robot minutes. On twins of a real arm
#: (0.1 mm / 0.01° per joint) it keeps false alarms within 5 % and finds every change that moves
#: targeting by more than 0.5 mm in 98–100 % of checks (``benchmarks/verify_check.py``); 6 samples
#: with both touches took 2.0 minutes and, on seeds not used to design it, 11 % false alarms.
DEFAULT_CHECK_POSES = 8
#: Which tools touch ``rtip1`` once in the check: the probe's touch is what tells a probe remount
#: from an image-transform change (both move the samples alike); the needle's sees needle changes
#: the samples already show.
TOUCH_CHOICES: dict[str, tuple[str, ...]] = {"both": ("needle", "probe"), "probe": ("probe",), "none": ()}
DEFAULT_TOUCHES = "probe"
CHECK_POSES_RANGE = (5, 16)
#: Per-coordinate noise (m) that scales the sensitivities: one pixel of 0.19 mm.
SENSITIVITY_SD_M = 0.19e-3
#: Prior SDs of the parameters (needle mm ×3, probe mm ×3, probe rad ×3, scale ×2) in SI.
_PRIOR = np.array([1e-3] * 3 + [1e-3] * 3 + [np.radians(1.0)] * 3 + [0.01] * 2)


@dataclass(frozen=True)
class CheckPlan:
    """The check's poses (a :class:`Plan` of the chosen ones, in visiting order) and its criterion.

    Attributes:
        plan: the chosen poses, ordered; its ``start_q`` the ready stance.
        chosen: indices of the chosen poses in the full plan's order of poses, in pick order.
        log_det: the criterion after each pick.
        motion_s: motion time from the ready stance through the poses (and back is not counted).
        touches: single touches planned on ``rtip1`` (the tools of :data:`TOUCH_CHOICES`).
    """

    plan: Plan
    chosen: list[int]
    log_det: list[float]
    motion_s: float
    touches: int
    touch_tools: tuple[str, ...] = ("needle", "probe")

    @property
    def robot_minutes(self) -> float:
        """Robot time of the check: samples at :data:`SECONDS_PER_SAMPLE`, motion, touches."""
        seconds = len(self.plan.poses) * SECONDS_PER_SAMPLE + self.motion_s + self.touches * SECONDS_PER_TOUCH
        return seconds / 60.0


def sensitivities(
    robot: Robot,
    q: FloatArray,
    uv_px: FloatArray,
    calibration: Calibration,
) -> FloatArray:
    """``(N, 3, 11)``: each pose's check residual (metres) per unit change of needle tip (3, m),
    probe mount (3 m, 3 rad) and image scale (2, relative), by central differences, about
    ``calibration`` (its tool transforms, ``T_Ptip_I`` and pixel spacing)."""
    # lazy: start-up (calibration.verify.check is loaded on first use)
    from brachycal.calibration.verify.check import ChainModel, CheckSession, NullModel

    null = NullModel(1.0, "", {"needle": 1.0, "probe": 1.0}, {"rtip1": np.zeros(3), "rtip2": np.zeros(3)})
    spacing_m = np.asarray(calibration.spacing_m, float)
    model = ChainModel(robot, calibration, null)
    session = CheckSession("", np.asarray(spacing_m, float), np.zeros(2), [], np.asarray(q), np.asarray(uv_px))
    columns = [*range(0, 9), 15, 16]
    h = 1e-6  # 1 µm, 1 µrad, 1 ppm: central differences, truncation ~h², far below any noise
    out = np.zeros((len(q), 3, 11))
    for k, j in enumerate(columns):
        dx = np.zeros(model.size)
        dx[j] = h
        plus, _ = model.residuals(dx, session)
        minus, _ = model.residuals(-dx, session)
        out[:, :, k] = (plus - minus) / (2 * h)
    return out


def choose_check_poses(J: FloatArray, count: int) -> tuple[list[int], list[float]]:
    """Greedy Bayesian D-optimal pick of ``count`` of the ``(N, 3, 11)`` sensitivities (module docstring)."""
    A = J * _PRIOR / SENSITIVITY_SD_M  # per prior SD and per noise SD: the information in prior units
    info = np.eye(J.shape[2])
    chosen: list[int] = []
    values: list[float] = []
    for _ in range(min(count, len(J))):
        best, best_value = -1, -np.inf
        for i in range(len(J)):
            if i in chosen:
                continue
            value = np.linalg.slogdet(info + A[i].T @ A[i])[1]
            if value > best_value:
                best, best_value = i, value
        chosen.append(best)
        values.append(float(best_value))
        info = info + A[best].T @ A[best]
    return chosen, values


def plan_check(
    full: Plan,
    robot: Robot,
    calibration: Calibration,
    *,
    count: int = DEFAULT_CHECK_POSES,
    touches: str = DEFAULT_TOUCHES,
) -> CheckPlan:
    """Choose ``count`` of ``full``'s poses for the check and order them (module docstring);
    ``touches`` (a :data:`TOUCH_CHOICES` key) says which tools touch ``rtip1`` once.

    ``calibration`` is a result's, or the robot's nominal tools: the choice depends on it only
    through the chain's geometry, which a few millimetres do not change.
    """
    check_int(count, "check poses", low=CHECK_POSES_RANGE[0], high=CHECK_POSES_RANGE[1])
    tools = touch_choice(touches)
    q = np.array([p.q for p in full.poses])
    uv = np.array([p.point.uv_px for p in full.poses])
    J = sensitivities(robot, q, uv, calibration)
    chosen, values = choose_check_poses(J, count)
    poses = [full.poses[i] for i in chosen]
    Q = np.array([full.start_q, *(p.q for p in poses)])
    times = ordering.move_times(Q, robot.velocity_limit, full.speed_scale)
    visit = ordering.nearest_neighbour_two_opt(times, start=0) - 1
    motion = ordering.path_time(visit + 1, times, start=0)
    plan = replace(
        full,
        poses=[poses[k] for k in visit],
        infeasible=[],
        motion_time_s={"optimised": motion},
    )
    return CheckPlan(plan, chosen, values, float(motion), len(tools), tools)


def nominal_calibration(robot: Robot, spacing_m: FloatArray) -> Calibration:
    """The calibration ``robot`` describes (its needle-tip, probe-tip and image frames) with the pixel
    spacing ``spacing_m`` ``(2,)`` m/px: what a check is planned about before (or without) a result."""
    # lazy: start-up (calibration is loaded on first use, as by sensitivities)
    from brachycal.calibration.result import Calibration, ImageCalibration

    frames = [robot.tool_transform(frame)[1] for frame in (NEEDLE_TIP, PROBE_TIP, US_IMAGE)]
    return Calibration(frames[0], frames[1], ImageCalibration("robot", frames[2], np.asarray(spacing_m, float)))


def touch_choice(touches: str) -> tuple[str, ...]:
    """The tools (session names) that touch ``rtip1`` for a :data:`TOUCH_CHOICES` key."""
    if touches not in TOUCH_CHOICES:
        raise InputError(f"touches must be one of {', '.join(TOUCH_CHOICES)}, not {touches!r}")
    return TOUCH_CHOICES[touches]
