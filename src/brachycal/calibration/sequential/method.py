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

The image-to-probe methods are alternatives, compared side by side: one method's refusal is that
method's finding (:attr:`SequentialResult.refused`, with its reason), and the others proceed. Only
when every method asked for refuses is the calibration refused (the first refusal, in the methods'
order): a tool step's refusal refuses it at once, since every method needs the tools.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from functools import partial
from typing import TYPE_CHECKING

import numpy as np

from brachycal._lazy import renamed
from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.parallel import parallel_calls
from brachycal.calibration.result import Calibration, ImageCalibration, Provenance, best_method, point_mm
from brachycal.calibration.result import locate as result_locate
from brachycal.calibration.sequential import image_to_probe
from brachycal.calibration.sequential.image_to_probe import METHODS
from brachycal.calibration.sequential.tool_rotation import ToolRotation, tool_rotation
from brachycal.calibration.sequential.tool_tips import (
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


@dataclass(frozen=True, repr=False)
class SequentialResult:
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
        refused: method → why the samples cannot determine it (the refusal's one line, naming the
            session file), for each method asked for that refused; those methods have no entry in
            ``image``, ``fit_residuals`` or ``loocv``.
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
    refused: dict[str, str] = field(default_factory=dict)

    def __repr__(self) -> str:
        """A few lines: samples, each tool's tip and Table I, each method's leave-one-out RMSE (mm)."""
        rmse = {m: s.rmse_mm for m, s in self.loocv.items()}
        best = self.calibration().method if self.image else None
        methods = ", ".join(f"{m} {r:.2f}" + (" (best)" if m == best else "") for m, r in rmse.items())
        lines = [
            f"SequentialResult: the sequential calibration of {len(self.sample_ids)} samples "
            "(transforms T_parent_child in metres; shown in mm)",
            *(
                f"  {name}  {tip} at {point_mm(tool.T_E_tool)} in the {arm} flange; Table I at rtip2: "
                f"MAE {tool.validation.mae_mm:.2f} mm over {tool.validation.n} trials"
                for name, tip, arm, tool in (
                    ("T_ER_Ntip", "needle_tip", "needle", self.needle),
                    ("T_EL_Ptip", "probe_tip", "probe", self.probe),
                )
            ),
            f"  T_Ptip_I   leave-one-out RMSE (mm): {methods or 'none'}",
        ]
        lines += [f"  refused    {m}: {why}" for m, why in self.refused.items()]
        if best is not None:
            lines.append(f"  .calibration(): the best method's ({best!r}) Calibration; write_result() writes it all")
        return "\n".join(lines)

    @property
    def T_ER_Ntip(self) -> FloatArray:
        return self.needle.T_E_tool

    @property
    def T_EL_Ptip(self) -> FloatArray:
        return self.probe.T_E_tool

    def calibration(self, method: str | None = None) -> Calibration:
        """The :class:`~brachycal.calibration.result.Calibration` of image method ``method`` (None:
        the lowest leave-one-out RMSE, :func:`~brachycal.calibration.result.best_method`), with the
        session's inputs as provenance.

        Raises:
            KeyError: no image calibration of that method.
        """
        if method is None:
            order = list(dict.fromkeys(m for m in (*METHODS, *self.image) if m in self.image))
            method = best_method(order, {m: s.rmse_mm for m, s in self.loocv.items()})
        return Calibration(
            self.T_ER_Ntip,
            self.T_EL_Ptip,
            self.image[method],
            image_size_px=self.image_size_px,
            provenance=Provenance(inputs=self.inputs),
        )


@contextmanager
def naming_file(file: str) -> Iterator[None]:
    """A DegenerateDataError raised inside, re-raised naming ``file`` when it names no file yet."""
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
    with naming_file("axes.csv"):
        T_R_E_p1, T_R_E_p2, T_R_E_p3 = (robot.fk(flange, axes[p]) for p in ("p1", "p2", "p3"))
        rotation = tool_rotation(T_R_E_p1, T_R_E_p2, T_R_E_p3, p_E_tool, tool=tool)
    return ToolCalibration(make_transform(rotation.R_E_tool, p_E_tool), validation, rotation, tip)


#: Cost of each image-to-probe method's leave-one-out (and all-sample fit), milliseconds of one core
#: on the 64-sample example session (`benchmarks/calibrate_speed.py`): ~35 for a closed-form method,
#: ICP's nearest-neighbour iterations from the all-sample fit 75, scaled u/v's iterative fits 95. They
#: only decide which process runs which method (:func:`~brachycal.calibration.parallel.parallel_calls`),
#: never a result; the same unit as the chain's costs, with which they share the cores.
METHOD_COST_MS = {"icp": 75.0, "scaled_uv": 95.0}
DEFAULT_METHOD_COST_MS = 35.0
#: Extra cost of ICP's all-sample fit (its global search from 49 starts), milliseconds as above.
ICP_FULL_COST_MS = 50.0

#: A method's all-sample fit and leave-one-out figures, or its refusal.
MethodOutcome = tuple[ImageCalibration, ErrorStats] | DegenerateDataError


@dataclass(frozen=True)
class SequentialPlan:
    """The sequential method cut where its independent work starts: the tools (Table I, computed
    here) and one call per image-to-probe method (its all-sample fit and leave-one-out), which may
    share the cores with other work (:func:`~brachycal.calibration.parallel.parallel_calls`).

    :func:`calibrate` is :meth:`prepare`, :meth:`calls`, then :meth:`result`.

    Attributes:
        session, robot, methods: what is calibrated, with which methods.
        reference_tips: reference tip → its estimate (``base_link``).
        needle, probe: the tools on their flanges.
        T_Ptip_I_init: ``(4, 4)`` ICP's prior.
        T_R_ER, T_R_EL: ``(N, 4, 4)`` the flanges at the image samples.
        p_Ptip: ``(N, 3)`` the needle tips in the probe frame (eq. 8); ``p_real`` ``(N, 3)`` in ``base_link``.
        start: ``(method, its all-sample fit)`` of the method the chain starts from (``scaled_uv``, else
            the first whose all-sample fit is not refused), computed here (:meth:`start_result`), or
            None if every method's was refused (then :meth:`result` raises the first refusal).
        start_refusals: method → the refusal of its all-sample fit, for the methods tried before
            :attr:`start` (:meth:`fit_method` returns it without fitting again).
    """

    session: Session
    robot: Robot
    methods: tuple[str, ...]
    reference_tips: dict[str, TipEstimate]
    needle: ToolCalibration
    probe: ToolCalibration
    T_Ptip_I_init: FloatArray
    T_R_ER: FloatArray
    T_R_EL: FloatArray
    p_Ptip: FloatArray
    p_real: FloatArray
    start: tuple[str, ImageCalibration] | None = None
    start_refusals: dict[str, DegenerateDataError] = field(default_factory=dict)

    @classmethod
    def prepare(
        cls,
        session: Session,
        robot: Robot,
        methods: tuple[str, ...] = METHODS,
        T_Ptip_I_init: FloatArray | None = None,
        *,
        fit_start: bool = False,
    ) -> SequentialPlan:
        """The tools (Table I) and the data of the image-to-probe fits (:func:`calibrate`'s arguments);
        ``fit_start``: also the all-sample fit of the method the chain starts from (:attr:`start`).

        Raises:
            DegenerateDataError: a tool step's conditioning check failed (names the session file).
        """
        needle_flange, probe_flange = robot.rig.needle_flange, robot.rig.probe_flange
        with naming_file("touches.csv"):
            check_distinct_touches(session.touches)
            reference_tips = {
                ref: reference_tip_estimate(
                    robot.fk(needle_flange, session.touches["top_model", ref].q), session.p_ER_Mtip
                )
                for ref in ("rtip1", "rtip2")
            }
            check_separation(reference_tips["rtip1"], reference_tips["rtip2"])
        for ref, tip in reference_tips.items():
            check_tip(tip, f"reference tip {ref}")
        needle = _tool(session, robot, "needle", reference_tips["rtip1"])
        probe = _tool(session, robot, "probe", reference_tips["rtip1"])
        if T_Ptip_I_init is None:
            T_Ptip_I_init = robot.tool_transform(US_IMAGE)[1]
        T_R_ER = robot.fk(needle_flange, session.samples_q)
        T_R_EL = robot.fk(probe_flange, session.samples_q)
        p_ER_Ntip = needle.T_E_tool[:3, 3]
        plan = cls(
            session,
            robot,
            tuple(methods),
            reference_tips,
            needle,
            probe,
            T_Ptip_I_init,
            T_R_ER,
            T_R_EL,
            image_to_probe.probe_points(T_R_ER, T_R_EL, p_ER_Ntip, probe.T_E_tool),
            transform_points(T_R_ER, p_ER_Ntip),
        )
        if not fit_start:
            return plan
        refusals: dict[str, DegenerateDataError] = {}
        for method in sorted(methods, key=lambda m: m != "scaled_uv"):  # scaled_uv first, then in order
            try:
                return replace(plan, start=(method, plan.full_fit(method)), start_refusals=refusals)
            except DegenerateDataError as exc:  # that method's finding: the next one starts the chain
                refusals[method] = exc
        return replace(plan, start_refusals=refusals)

    def full_fit(self, method: str) -> ImageCalibration:
        """``method``'s fit on all samples (warns in the grey zone, as :func:`image_to_probe.fit`)."""
        with naming_file("samples.csv"):
            return image_to_probe.fit(
                method, self.session.uv_px, self.p_Ptip, self.session.spacing_m, self.T_Ptip_I_init
            )

    def fit_method(self, method: str) -> MethodOutcome:
        """``method``'s all-sample fit and its leave-one-out figures (Table II), or its refusal."""
        if method in self.start_refusals:
            return self.start_refusals[method]
        try:
            full = self.start[1] if self.start is not None and self.start[0] == method else self.full_fit(method)
            with naming_file("samples.csv"):
                loo = image_to_probe.leave_one_out(
                    method,
                    self.session.uv_px,
                    self.T_R_ER,
                    self.T_R_EL,
                    self.needle.T_E_tool[:3, 3],
                    self.probe.T_E_tool,
                    self.session.spacing_m,
                    self.T_Ptip_I_init,
                    full=full,
                )
        except DegenerateDataError as exc:  # this method's refusal: result() records it
            return exc
        return full, loo

    def calls(self) -> tuple[list[Callable[[], MethodOutcome]], list[float]]:
        """One call per method (:meth:`fit_method`, in the methods' order) and their costs
        (:data:`METHOD_COST_MS`)."""
        calls: list[Callable[[], MethodOutcome]] = [partial(self.fit_method, m) for m in self.methods]
        costs = [
            0.0
            if m in self.start_refusals
            else METHOD_COST_MS.get(m, DEFAULT_METHOD_COST_MS)
            + (ICP_FULL_COST_MS if m == "icp" and (self.start is None or self.start[0] != m) else 0.0)
            for m in self.methods
        ]
        return calls, costs

    def start_result(self) -> SequentialResult:
        """What the chain starts from (:meth:`ParameterLayout.start`): the tools, the reference tips
        and :attr:`start`'s image calibration, before any leave-one-out figure (those stay empty).

        Raises:
            ValueError: the plan was prepared without ``fit_start``, or that fit was refused.
        """
        if self.start is None:
            raise ValueError("no starting image calibration: prepare(..., fit_start=True) and check start")
        method, full = self.start
        return self._result({method: full}, {}, {})

    def result(self, outcomes: list[MethodOutcome]) -> SequentialResult:
        """The :class:`SequentialResult` from :meth:`calls`' outcomes (methods' order); a refused
        method is recorded in :attr:`SequentialResult.refused` and the others proceed.

        Raises:
            DegenerateDataError: every method refused: the first refusal, in the methods' order.
        """
        image, residuals, loocv, refused = {}, {}, {}, {}
        for method, outcome in zip(self.methods, outcomes, strict=True):
            if isinstance(outcome, DegenerateDataError):
                refused[method] = outcome
                continue
            image[method], loocv[method] = outcome
            p_cal = image_to_probe.predict_base(image[method], self.T_R_EL, self.probe.T_E_tool, self.session.uv_px)
            residuals[method] = ErrorStats.between(self.p_real, p_cal)
        if refused and not image:  # nothing left to calibrate the image with
            raise next(iter(refused.values()))
        return self._result(image, residuals, loocv, {m: str(exc) for m, exc in refused.items()})

    def _result(
        self,
        image: dict[str, ImageCalibration],
        residuals: dict[str, ErrorStats],
        loocv: dict[str, ErrorStats],
        refused: dict[str, str] | None = None,
    ) -> SequentialResult:
        session = self.session
        return SequentialResult(
            p_R_Rtip={ref: tip.p for ref, tip in self.reference_tips.items()},
            needle=self.needle,
            probe=self.probe,
            image=image,
            fit_residuals=residuals,
            loocv=loocv,
            sample_ids=list(session.sample_ids),
            inputs=dict(session.inputs),
            reference_tips=self.reference_tips,
            image_size_px=(int(session.size_px[0]), int(session.size_px[1])),
            refused=dict(refused or {}),
        )


def calibrate(
    session: Session,
    robot: Robot,
    methods: tuple[str, ...] = METHODS,
    T_Ptip_I_init: FloatArray | None = None,
) -> SequentialResult:
    """Run the sequential calibration on a validated session.

    Args:
        session: the recorded data.
        robot: kinematic model giving the flange poses: its rig's needle flange (the paper's ER, the
            SDA10F's right ``tool0``) and probe flange (EL); any dual-arm robot with a description.
        methods: registration methods to fit and cross-validate (default: all).
        T_Ptip_I_init: ``(4, 4)`` ICP's prior; default: the model's ``us_image`` frame.

    Returns:
        the result; a method whose samples cannot determine it is in its ``refused`` (with the reason),
        the others are fitted.

    Raises:
        DegenerateDataError: a tool step's conditioning check failed, or every method refused; the
            message names the session file.
    """
    plan = SequentialPlan.prepare(session, robot, methods, T_Ptip_I_init)
    # The methods are independent: they share the cores, each computed as alone.
    return plan.result(parallel_calls(*plan.calls()))


def loo_points(session: Session, robot: Robot, result: SequentialResult, method: str) -> tuple[FloatArray, FloatArray]:
    """``(P_real (N, 3), P_cal (N, 3))`` of one method's leave-one-out, for figures (Fig. 10).

    The same folds as :attr:`SequentialResult.loocv`, ICP started from the model's ``us_image``.
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
    robot: Robot,
    q: FloatArray,
    uv_px: FloatArray,
    calibration: Calibration | FloatArray,
    image: ImageCalibration | None = None,
) -> FloatArray:
    """Targeting: image pixels ``(N, 2)`` → ``p_R (N, 3)`` in the robot's base frame at configuration(s)
    ``q`` with ``calibration`` (:func:`brachycal.calibration.result.locate`).

    ``p_R = T_R_EL(q) @ T_EL_Ptip @ T_Ptip_I @ p_I`` with ``p_I = (u·s_u, v·s_v, 0)``.

    The loose form ``locate(robot, q, uv_px, T_EL_Ptip, image)`` still works for one release, with a
    :class:`DeprecationWarning`.
    """
    if isinstance(calibration, Calibration):
        if image is not None:
            raise TypeError("locate() takes a Calibration alone, or the deprecated (T_EL_Ptip, image)")
        return result_locate(robot, q, uv_px, calibration)
    if image is None:
        raise TypeError("locate() needs a Calibration")
    warnings.warn(
        "locate(robot, q, uv_px, T_EL_Ptip, image) is deprecated: pass one Calibration "
        "(locate(robot, q, uv_px, calibration))",
        DeprecationWarning,
        stacklevel=2,
    )
    q = np.asarray(q, dtype=float)
    return image_to_probe.predict_base(image, robot.fk(robot.rig.probe_flange, q), calibration, uv_px)


#: Former names, given for one release with a DeprecationWarning.
if not TYPE_CHECKING:  # type checkers see only the new names
    __getattr__ = renamed(__name__, {"CalibrationResult": "SequentialResult"})
