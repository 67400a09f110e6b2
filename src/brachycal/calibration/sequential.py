"""The paper's sequential calibration, end to end: tips, rotations, image-to-probe, validation.

Order (Fig. 5): reference tips from the top-model (eq. 4); needle and probe tips (eqs. 5, 6) with
Table I at the second reference tip; tool rotations from three points (eq. 7); the needle tips
in the probe frame (eq. 8); ``T_Ptip_I`` by every registration method (eq. 9) with leave-one-out
figures (Table II). Flange poses come from the robot model's forward kinematics; the model's
own ``us_image`` frame only serves ICP as a prior (one start among many, and the tie-breaker).

Every step checks its conditioning (see each module) and refuses data that cannot determine its
estimate with :class:`~brachycal.errors.DegenerateDataError`, naming the session file the data came
from (``touches.csv``, ``axes.csv``, ``samples.csv``); grey-zone estimates warn
(:class:`~brachycal.errors.ConditioningWarning`). Each estimate carries its predicted uncertainty.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from brachycal.calibration import image_to_probe
from brachycal.calibration.image_to_probe import METHODS, ImageCalibration
from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.parallel import available_workers, parallel_map
from brachycal.calibration.tool_rotation import ToolRotation, tool_rotation
from brachycal.calibration.tool_tips import (
    TipEstimate,
    check_distinct_touches,
    check_separation,
    check_tip,
    reference_tip_estimate,
    tool_tip_estimate,
    validate_tip,
)
from brachycal.data.session import Session
from brachycal.errors import DegenerateDataError
from brachycal.model.names import US_IMAGE
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray, make_transform, transform_points


def tool_flange(robot: Robot, tool: str) -> str:
    """The flange link carrying ``tool`` (``needle``, ``top_model``: the needle arm's; ``probe``: the
    probe arm's), from the robot's rig (:attr:`Robot.rig`; the SDA10F's right and left ``tool0``)."""
    rig = robot.rig
    return rig.probe_flange if tool == "probe" else rig.needle_flange


@dataclass(frozen=True)
class ToolCalibration:
    """One tool on its flange.

    Attributes:
        T_E_tool: ``(4, 4)`` the tool frame in its flange frame (``T_ER_Ntip`` or ``T_EL_Ptip``).
        validation: Table I figures at the validation tip ``rtip2``.
        rotation: the three-point rotation and its axis-angle quality figure.
        tip: the tip estimate with its per-trial values and predicted covariance.
    """

    T_E_tool: FloatArray
    validation: ErrorStats
    rotation: ToolRotation
    tip: TipEstimate | None = None


@dataclass(frozen=True)
class CalibrationResult:
    """Everything the sequential method estimates and measures (SI units).

    Attributes:
        p_R_Rtip: reference tip → ``(3,)`` position in ``base_link`` located with the top-model.
        needle: ``T_ER_Ntip`` and its figures.
        probe: ``T_EL_Ptip`` and its figures.
        image: method → :class:`ImageCalibration` fitted on all samples.
        fit_residuals: method → residuals of that fit on its own samples (in ``base_link``).
        loocv: method → leave-one-out figures (Table II).
        sample_ids: names of the samples, in the order of the per-sample errors.
        inputs: session file → SHA-256.
        image_size_px: ``(width, height)`` of the session's images, pixels (what a pixel given
            to the calibration later must lie inside); None if not known.
    """

    p_R_Rtip: dict[str, FloatArray]
    needle: ToolCalibration
    probe: ToolCalibration
    image: dict[str, ImageCalibration]
    fit_residuals: dict[str, ErrorStats]
    loocv: dict[str, ErrorStats]
    sample_ids: list[str]
    inputs: dict[str, str] = field(default_factory=dict)
    reference_tips: dict[str, TipEstimate] = field(default_factory=dict)
    image_size_px: tuple[int, int] | None = None

    @property
    def T_ER_Ntip(self) -> FloatArray:
        return self.needle.T_E_tool

    @property
    def T_EL_Ptip(self) -> FloatArray:
        return self.probe.T_E_tool


@contextmanager
def _data_of(file: str) -> Iterator[None]:
    """Name the session file in a refusal that does not name one yet."""
    try:
        yield
    except DegenerateDataError as exc:
        if exc.file is not None:
            raise
        raise DegenerateDataError(exc.problem, file=file) from None


def _tool(session: Session, robot: Robot, tool: str, rtip1: TipEstimate) -> ToolCalibration:
    flange = tool_flange(robot, tool)
    tip = tool_tip_estimate(robot.fk(flange, session.touches[tool, "rtip1"].q), rtip1)
    check_tip(tip, f"{tool} tip")
    p_E_tool = tip.p
    validation = validate_tip(
        robot.fk(flange, session.touches[tool, "rtip2"].q),
        p_E_tool,
        robot.fk(robot.rig.needle_flange, session.touches["top_model", "rtip2"].q),
        session.p_ER_Mtip,
    )
    axes = session.axes[tool]
    with _data_of("axes.csv"):
        T_R_E_p1, T_R_E_p2, T_R_E_p3 = (robot.fk(flange, axes[p]) for p in ("p1", "p2", "p3"))
        rotation = tool_rotation(T_R_E_p1, T_R_E_p2, T_R_E_p3, p_E_tool, tool=tool)
    return ToolCalibration(make_transform(rotation.R_E_tool, p_E_tool), validation, rotation, tip)


#: Relative cost of each image-to-probe method's fit and leave-one-out (64 samples): ICP's
#: multi-start nearest-neighbour iterations cost about three closed-form fits.
METHOD_COST = {"icp": 3.0}


def _method_groups(methods: tuple[str, ...], workers: int) -> list[tuple[str, ...]]:
    """``methods`` in at most ``workers`` groups of about equal cost (:data:`METHOD_COST`, 1 by default),
    the costliest placed first (each into the cheapest group so far)."""
    groups: list[list[str]] = [[] for _ in range(max(1, min(workers, len(methods))))]
    costs = [0.0] * len(groups)
    for method in sorted(methods, key=lambda m: -METHOD_COST.get(m, 1.0)):
        k = costs.index(min(costs))
        groups[k].append(method)
        costs[k] += METHOD_COST.get(method, 1.0)
    return [tuple(g) for g in groups if g]


def calibrate(
    session: Session,
    robot: Robot,
    methods: tuple[str, ...] = METHODS,
    T_Ptip_I_init: FloatArray | None = None,
) -> CalibrationResult:
    """Run the sequential calibration on a validated session.

    Args:
        session: the recorded data.
        robot: kinematic model giving the flange poses: its rig's needle flange (the paper's ER, the
            SDA10F's right ``tool0``) and probe flange (EL); any dual-arm robot with a description.
        methods: registration methods to fit and cross-validate (default: all).
        T_Ptip_I_init: ``(4, 4)`` ICP's prior; default: the model's ``us_image`` frame.

    Raises:
        DegenerateDataError: a step's conditioning check failed; the message names the session file.
    """
    needle_flange, probe_flange = robot.rig.needle_flange, robot.rig.probe_flange
    with _data_of("touches.csv"):
        check_distinct_touches(session.touches)
        reference_tips = {
            ref: reference_tip_estimate(robot.fk(needle_flange, session.touches["top_model", ref].q), session.p_ER_Mtip)
            for ref in ("rtip1", "rtip2")
        }
        check_separation(reference_tips["rtip1"], reference_tips["rtip2"])
    for ref, tip in reference_tips.items():
        check_tip(tip, f"reference tip {ref}")
    p_R_Rtip = {ref: tip.p for ref, tip in reference_tips.items()}
    needle = _tool(session, robot, "needle", reference_tips["rtip1"])
    probe = _tool(session, robot, "probe", reference_tips["rtip1"])
    if T_Ptip_I_init is None:
        T_Ptip_I_init = robot.tool_transform(US_IMAGE)[1]

    T_R_ER = robot.fk(needle_flange, session.samples_q)
    T_R_EL = robot.fk(probe_flange, session.samples_q)
    p_ER_Ntip = needle.T_E_tool[:3, 3]
    p_Ptip = image_to_probe.probe_points(T_R_ER, T_R_EL, p_ER_Ntip, probe.T_E_tool)
    p_real = transform_points(T_R_ER, p_ER_Ntip)

    def fit_methods(group: tuple[str, ...]) -> dict[str, tuple[ImageCalibration, ErrorStats] | DegenerateDataError]:
        """Each method's fit on all samples and its leave-one-out figures (or its refusal)."""
        out: dict[str, tuple[ImageCalibration, ErrorStats] | DegenerateDataError] = {}
        for method in group:
            try:
                with _data_of("samples.csv"):
                    full = image_to_probe.fit(method, session.uv_px, p_Ptip, session.spacing_m, T_Ptip_I_init)
                    loo = image_to_probe.leave_one_out(
                        method,
                        session.uv_px,
                        T_R_ER,
                        T_R_EL,
                        p_ER_Ntip,
                        probe.T_E_tool,
                        session.spacing_m,
                        T_Ptip_I_init,
                        full=full,
                    )
            except DegenerateDataError as exc:  # raised below in the methods' order, as in turn
                out[method] = exc
            else:
                out[method] = (full, loo)
        return out

    # The methods are independent: they share the cores (parallel_map), each computed as alone.
    fitted: dict[str, tuple[ImageCalibration, ErrorStats] | DegenerateDataError] = {}
    for part in parallel_map(fit_methods, _method_groups(methods, available_workers())):
        fitted.update(part)
    image, residuals, loocv = {}, {}, {}
    for method in methods:
        outcome = fitted[method]
        if isinstance(outcome, DegenerateDataError):  # the first method that fails, as in turn
            raise outcome
        image[method], loocv[method] = outcome
        p_cal = image_to_probe.predict_base(image[method], T_R_EL, probe.T_E_tool, session.uv_px)
        residuals[method] = ErrorStats.between(p_real, p_cal)
    return CalibrationResult(
        p_R_Rtip=p_R_Rtip,
        needle=needle,
        probe=probe,
        image=image,
        fit_residuals=residuals,
        loocv=loocv,
        sample_ids=list(session.sample_ids),
        inputs=dict(session.inputs),
        reference_tips=reference_tips,
        image_size_px=(int(session.size_px[0]), int(session.size_px[1])),
    )


def loo_points(session: Session, robot: Robot, result: CalibrationResult, method: str) -> tuple[FloatArray, FloatArray]:
    """``(P_real (N, 3), P_cal (N, 3))`` of one method's leave-one-out, for figures (Fig. 10).

    The same folds as :attr:`CalibrationResult.loocv`, ICP started from the model's ``us_image``.
    """
    return image_to_probe.leave_one_out_points(
        method,
        session.uv_px,
        robot.fk(robot.rig.needle_flange, session.samples_q),
        robot.fk(robot.rig.probe_flange, session.samples_q),
        result.T_ER_Ntip[:3, 3],
        result.T_EL_Ptip,
        session.spacing_m,
        robot.tool_transform(US_IMAGE)[1],
    )


def locate(
    robot: Robot, q: FloatArray, uv_px: FloatArray, T_EL_Ptip: FloatArray, calibration: ImageCalibration
) -> FloatArray:
    """Targeting: image pixels ``(N, 2)`` → ``p_R (N, 3)`` in the robot's base frame at configuration(s) ``q``
    (``T_R_EL`` is the rig's probe flange).

    ``p_R = T_R_EL(q) @ T_EL_Ptip @ T_Ptip_I @ p_I`` with ``p_I = (u·s_u, v·s_v, 0)``.
    """
    q = np.asarray(q, dtype=float)
    return image_to_probe.predict_base(calibration, robot.fk(robot.rig.probe_flange, q), T_EL_Ptip, uv_px)
