"""The paper's sequential calibration, end to end: tips, rotations, image-to-probe, validation.

Order (Fig. 5): reference tips from the top-model (eq. 4); needle and probe tips (eqs. 5, 6) with
Table I at the second reference tip; tool rotations from three points (eq. 7); the needle tips
in the probe frame (eq. 8); ``T_Ptip_I`` by every registration method (eq. 9) with leave-one-out
figures (Table II). Flange poses come from the robot model's forward kinematics; the model's
own tool frames only serve as ICP's initial guess.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from brachycal.calibration import image_to_probe
from brachycal.calibration.image_to_probe import METHODS, ImageCalibration
from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.tool_rotation import ToolRotation, tool_rotation
from brachycal.calibration.tool_tips import reference_tip, tool_tip, validate_tip
from brachycal.data.session import Session
from brachycal.model.names import LEFT_FLANGE, RIGHT_FLANGE, US_IMAGE
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray, make_transform, transform_points

#: Which flange carries which tool.
TOOL_FLANGE = {"needle": RIGHT_FLANGE, "top_model": RIGHT_FLANGE, "probe": LEFT_FLANGE}


@dataclass(frozen=True)
class ToolCalibration:
    """One tool on its flange.

    Attributes:
        T_E_tool: ``(4, 4)`` the tool frame in its flange frame (``T_ER_Ntip`` or ``T_EL_Ptip``).
        validation: Table I figures at the validation tip ``rtip2``.
        rotation: the three-point rotation and its axis-angle quality figure.
    """

    T_E_tool: FloatArray
    validation: ErrorStats
    rotation: ToolRotation


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
    """

    p_R_Rtip: dict[str, FloatArray]
    needle: ToolCalibration
    probe: ToolCalibration
    image: dict[str, ImageCalibration]
    fit_residuals: dict[str, ErrorStats]
    loocv: dict[str, ErrorStats]
    sample_ids: list[str]
    inputs: dict[str, str] = field(default_factory=dict)

    @property
    def T_ER_Ntip(self) -> FloatArray:
        return self.needle.T_E_tool

    @property
    def T_EL_Ptip(self) -> FloatArray:
        return self.probe.T_E_tool


def _tool(session: Session, robot: Robot, tool: str, p_R_Rtip1: FloatArray) -> ToolCalibration:
    flange = TOOL_FLANGE[tool]
    p_E_tool = tool_tip(robot.fk(flange, session.touches[tool, "rtip1"].q), p_R_Rtip1)
    validation = validate_tip(
        robot.fk(flange, session.touches[tool, "rtip2"].q),
        p_E_tool,
        robot.fk(RIGHT_FLANGE, session.touches["top_model", "rtip2"].q),
        session.p_ER_Mtip,
    )
    axes = session.axes[tool]
    rotation = tool_rotation(*(robot.fk(flange, axes[p]) for p in ("p1", "p2", "p3")), p_E_tool)
    return ToolCalibration(make_transform(rotation.R_E_tool, p_E_tool), validation, rotation)


def calibrate(
    session: Session,
    robot: Robot,
    methods: tuple[str, ...] = METHODS,
    T_Ptip_I_init: FloatArray | None = None,
) -> CalibrationResult:
    """Run the sequential calibration on a validated session.

    Args:
        session: the recorded data.
        robot: kinematic model giving the flange poses (the URDF's flanges).
        methods: registration methods to fit and cross-validate (default: all).
        T_Ptip_I_init: ``(4, 4)`` ICP's initial guess; default: the model's ``us_image`` frame.
    """
    p_R_Rtip = {
        ref: reference_tip(robot.fk(RIGHT_FLANGE, session.touches["top_model", ref].q), session.p_ER_Mtip)
        for ref in ("rtip1", "rtip2")
    }
    needle = _tool(session, robot, "needle", p_R_Rtip["rtip1"])
    probe = _tool(session, robot, "probe", p_R_Rtip["rtip1"])
    if T_Ptip_I_init is None:
        T_Ptip_I_init = robot.tool_transform(US_IMAGE)[1]

    T_R_ER = robot.fk(RIGHT_FLANGE, session.samples_q)
    T_R_EL = robot.fk(LEFT_FLANGE, session.samples_q)
    p_ER_Ntip = needle.T_E_tool[:3, 3]
    p_Ptip = image_to_probe.probe_points(T_R_ER, T_R_EL, p_ER_Ntip, probe.T_E_tool)
    p_real = transform_points(T_R_ER, p_ER_Ntip)
    image, residuals, loocv = {}, {}, {}
    for method in methods:
        image[method] = image_to_probe.fit(method, session.uv_px, p_Ptip, session.spacing_m, T_Ptip_I_init)
        p_cal = image_to_probe.predict_base(image[method], T_R_EL, probe.T_E_tool, session.uv_px)
        residuals[method] = ErrorStats.between(p_real, p_cal)
        loocv[method] = image_to_probe.leave_one_out(
            method, session.uv_px, T_R_ER, T_R_EL, p_ER_Ntip, probe.T_E_tool, session.spacing_m, T_Ptip_I_init
        )
    return CalibrationResult(
        p_R_Rtip=p_R_Rtip,
        needle=needle,
        probe=probe,
        image=image,
        fit_residuals=residuals,
        loocv=loocv,
        sample_ids=list(session.sample_ids),
        inputs=dict(session.inputs),
    )


def loo_points(session: Session, robot: Robot, result: CalibrationResult, method: str) -> tuple[FloatArray, FloatArray]:
    """``(P_real (N, 3), P_cal (N, 3))`` of one method's leave-one-out, for figures (Fig. 10).

    The same folds as :attr:`CalibrationResult.loocv`, ICP started from the model's ``us_image``.
    """
    return image_to_probe.leave_one_out_points(
        method,
        session.uv_px,
        robot.fk(RIGHT_FLANGE, session.samples_q),
        robot.fk(LEFT_FLANGE, session.samples_q),
        result.T_ER_Ntip[:3, 3],
        result.T_EL_Ptip,
        session.spacing_m,
        robot.tool_transform(US_IMAGE)[1],
    )


def locate(
    robot: Robot, q: FloatArray, uv_px: FloatArray, T_EL_Ptip: FloatArray, calibration: ImageCalibration
) -> FloatArray:
    """Targeting: image pixels ``(N, 2)`` → ``p_R (N, 3)`` in ``base_link`` at configuration(s) ``q``.

    ``p_R = T_R_EL(q) @ T_EL_Ptip @ T_Ptip_I @ p_I`` with ``p_I = (u·s_u, v·s_v, 0)``.
    """
    q = np.asarray(q, dtype=float)
    return image_to_probe.predict_base(calibration, robot.fk(LEFT_FLANGE, q), T_EL_Ptip, uv_px)
