"""Robot identification from an external tracker: any arm, a marker on it seen in 3-D or 6-D.

``T_tracker_marker(n) = T_tracker_base · T_base_flange(q_n; c) · T_flange_marker``: the tracker's
frame and the marker's place on the flange are unknown (the protocol's own unknowns of
:func:`~brachycal.calibration.robot.arm_fit.fit_arm`), the robot's geometry ``c`` is one of
:data:`TRACKER_MODELS` (the URDF as it is, joint zeros, every joint-origin component), reduced to
what the data can see (the base set) and fitted with the stated accuracy as prior. Residuals are
positions (metres) and, 6-D, orientations (radians), each kind with its own estimated noise level.

The headline figure is leave-one-out over postures, training second; a richer model is returned
only if its held-out error beats the smaller one's by more than the paired differences' standard
error (:func:`identify_from_tracker`). The prior is the stated accuracy, or (``prior="evidence"``)
the per-joint SDs the postures' own evidence makes most likely (:func:`tracker_evidence_prior`), chosen
inside each leave-one-out fold from that fold's postures alone. Units: metres, radians; frames as named.

Design: ``docs/design/robot_identification.md`` ("From an external tracker").
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from brachycal.calibration.chain.robot_terms import joint_twists
from brachycal.calibration.robot.arm_fit import (
    ArmFit,
    Evaluation,
    ParameterSelection,
    corrected_robot,
    fit_arm,
    flange_points,
    prior_sd,
)
from brachycal.calibration.robot.defaults import TRACKER_ACCURACY, TRACKER_MODELS, TRACKER_PRIORS
from brachycal.calibration.robot.evidence import EvidenceChoice, evidence_search
from brachycal.calibration.robot.identifiability import COMPONENTS
from brachycal.calibration.robot_accuracy import RobotAccuracy
from brachycal.calibration.sequential.registration import kabsch
from brachycal.data.formats.tracker_table import TrackerTable, read_tracker_columns, read_tracker_table
from brachycal.errors import DegenerateDataError, InputError
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray, left_jacobian, make_transform, nearest_rotation, rotation, skew

__all__ = [
    "TRACKER_ACCURACY",
    "TRACKER_MODELS",
    "TRACKER_PRIORS",
    "ModelScore",
    "TrackerData",
    "TrackerFit",
    "TrackerIdentification",
    "TrackerResiduals",
    "fit_tracker",
    "identify_from_tracker",
    "identify_tracker_file",
    "leave_one_out",
    "model_selection",
    "select_parameters",
    "start_frames",
    "tracker_data",
    "tracker_evidence_prior",
    "tracker_fits",
]

#: Rounds of the starting frames' alternation (registration, marker) at most.
START_ROUNDS = 50
#: Joint readings beyond a limit by at most this are accepted (real encoders read a little past
#: the URDF's limits: TIAGo's torso lift at 0.35018 m of 0.35 in FIGAROH's data); further is refused.
LIMIT_TOLERANCE_RAD = 1e-2
LIMIT_TOLERANCE_M = 1e-3
#: Starting noise levels: tracker position (m) and orientation (rad).
START_SIGMA = {"position": 1e-3, "orientation": float(np.radians(0.5))}


@dataclass(frozen=True)
class TrackerData:
    """A tracker table placed on a robot: configurations, the flange, the measurements.

    Attributes:
        robot: the nominal robot (its URDF).
        flange: the frame the marker is rigidly on.
        Q: ``(N, nq)`` configurations (joints not in the table held at 0; none of them moves the flange).
        p: ``(N, 3)`` measured marker positions in the tracker's frame (metres).
        R: ``(N, 3, 3)`` measured orientations, or ``None`` (3-D marker).
        rows: file rows of the postures.
    """

    robot: Robot
    flange: str
    Q: FloatArray
    p: FloatArray
    R: FloatArray | None
    rows: tuple[int, ...] = ()

    @property
    def six_d(self) -> bool:
        return self.R is not None

    def subset(self, keep: np.ndarray) -> TrackerData:
        R = None if self.R is None else self.R[keep]
        rows = tuple(np.asarray(self.rows)[keep].tolist()) if self.rows else ()
        return TrackerData(self.robot, self.flange, self.Q[keep], self.p[keep], R, rows)


def tracker_data(robot: Robot, table: TrackerTable, flange: str | None = None) -> TrackerData:
    """The table placed on ``robot``; ``flange`` defaults to the frame of the table's last joint.

    Raises:
        InputError: a joint column the robot does not have, a joint that moves the flange missing
            from the table, or a joint value beyond its limits, naming it.
    """
    names = list(robot.joint_names)
    for name in table.joint_names:
        if name not in names:
            raise InputError(f"the robot has no joint {name!r}", file=table.source, row=1, column=name)
    flange = flange or table.joint_names[-1]
    robot.frame_id(flange)
    W = joint_twists(robot, robot.neutral()[None], flange)[0]
    moving = [n for j, n in enumerate(names) if np.any(W[j]) and n not in table.joint_names]
    if moving:
        raise InputError(
            f"joint {moving[0]!r} moves {flange!r} but has no column in the table", file=table.source, row=1
        )
    Q = np.zeros((len(table), robot.nq))
    index = [names.index(n) for n in table.joint_names]
    Q[:, index] = table.Q
    for j, name in zip(index, table.joint_names, strict=True):
        tol = LIMIT_TOLERANCE_M if robot.in_metres[j] else LIMIT_TOLERANCE_RAD
        bad = np.flatnonzero((Q[:, j] < robot.lower[j] - tol) | (Q[:, j] > robot.upper[j] + tol))
        if bad.size:
            k = int(bad[0])
            raise InputError(
                f"{Q[k, j]:g} is beyond the joint's limits [{robot.lower[j]:g}, {robot.upper[j]:g}]",
                file=table.source,
                row=table.rows[k],
                column=name,
            )
    return TrackerData(robot, flange, Q, table.p_tracker_marker, table.R_tracker_marker, table.rows)


# --- the residuals ---------------------------------------------------------------------------


def _D(xi: FloatArray) -> FloatArray:
    """``(4, 4)`` ``T(exp(ω), v)`` of ``ξ = (v, ω)`` (:func:`corrected_robot`'s parameterisation)."""
    return make_transform(rotation(xi[3:]), xi[:3])


def _log(R: FloatArray) -> FloatArray:
    """``(N, 3)`` rotation vectors of ``(N, 3, 3)`` rotations."""
    return Rotation.from_matrix(R).as_rotvec()


@dataclass(frozen=True)
class TrackerResiduals:
    """The tracker's residuals (:class:`~brachycal.calibration.robot.arm_fit.ResidualModel`).

    ``y = (ξ_base (6), marker (3 or 6))`` about starting frames: ``T_tracker_base = T0_base · T(ξ_base)``;
    a 3-D marker at ``p0 + y_marker``, a 6-D one at ``T0_marker · T(ξ_marker)`` (``T(v, ω) =
    [exp ω, v]``). Rows per posture: the position residual (3, group ``position``, metres) and,
    6-D, ``log(R_pred R_measᵀ)`` (3, group ``orientation``, radians, tracker frame).
    """

    data: TrackerData
    T0_base: FloatArray
    T0_marker: FloatArray

    @property
    def groups(self) -> tuple[str, ...]:
        return ("position", "orientation") if self.data.six_d else ("position",)

    @property
    def ny(self) -> int:
        return 12 if self.data.six_d else 9

    def y_scale(self) -> FloatArray:
        return np.full(self.ny, 1e-3)

    def frames(self, y: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``(T_tracker_base, T_flange_marker)`` at ``y``."""
        T_tb = self.T0_base @ _D(y[:6])
        if self.data.six_d:
            return T_tb, self.T0_marker @ _D(y[6:12])
        T_fm = self.T0_marker.copy()
        T_fm[:3, 3] += y[6:9]
        return T_tb, T_fm

    def evaluate(self, robot: Robot, y: FloatArray) -> Evaluation:
        d = self.data
        N, nc = len(d.Q), 6 * robot.nq
        T_tb, T_fm = self.frames(y)
        marker = flange_points(robot, d.Q, d.flange, T_fm[:3, 3])  # the marker in the base frame
        x_b, W = marker.p, marker.W
        R_tb = T_tb[:3, :3]
        R_tf = R_tb @ marker.R
        r_p = x_b @ R_tb.T + T_tb[:3, 3] - d.p
        J_c = (R_tb @ marker.J_c).reshape(3 * N, nc)
        J_y = np.zeros((N, 3, self.ny))
        J_y[:, :, :3] = self.T0_base[:3, :3]
        J_y[:, :, 3:6] = -R_tb @ skew(x_b) @ left_jacobian(-y[3:6])
        if not d.six_d or d.R is None:
            J_y[:, :, 6:9] = R_tf
            return Evaluation(r_p.ravel(), J_c, J_y.reshape(3 * N, self.ny), np.zeros(3 * N, dtype=int))
        J_y[:, :, 6:9] = R_tf @ self.T0_marker[:3, :3]
        R_pred = R_tf @ T_fm[:3, :3]
        r_o = _log(R_pred @ np.swapaxes(d.R, 1, 2))
        J_inv = np.linalg.inv(np.array([left_jacobian(r) for r in r_o]))  # d log / d (world-side turn)
        Jo_c = J_inv @ (R_tb @ W[:, :, 3:, :]).transpose(0, 2, 1, 3).reshape(N, 3, nc)
        Jo_y = np.zeros((N, 3, self.ny))
        Jo_y[:, :, 3:6] = R_tb @ left_jacobian(-y[3:6])
        Jo_y[:, :, 9:12] = R_pred @ left_jacobian(-y[9:12])
        Jo_y = J_inv @ Jo_y
        return Evaluation(
            np.concatenate([r_p.ravel(), r_o.ravel()]),
            np.vstack([J_c, Jo_c.reshape(3 * N, nc)]),
            np.vstack([J_y.reshape(3 * N, self.ny), Jo_y.reshape(3 * N, self.ny)]),
            np.concatenate([np.zeros(3 * N, dtype=int), np.ones(3 * N, dtype=int)]),
        )


# --- starting values -------------------------------------------------------------------------


def start_frames(data: TrackerData) -> tuple[FloatArray, FloatArray]:
    """``(T_tracker_base, T_flange_marker)`` of the nominal robot: rigid registrations alternated
    with the marker's linear least squares (the frames' problem is nearly linear once near)."""
    T_bf = data.robot.fk(data.flange, data.Q)
    p_fm: FloatArray = np.zeros(3)
    T_tb = np.eye(4)
    for _ in range(START_ROUNDS):
        x_b = T_bf[:, :3, :3] @ p_fm + T_bf[:, :3, 3]
        T_tb = kabsch(x_b, data.p)
        A = (T_tb[:3, :3] @ T_bf[:, :3, :3]).reshape(-1, 3)
        b = (data.p - T_tb[:3, 3] - T_bf[:, :3, 3] @ T_tb[:3, :3].T).ravel()
        new = np.asarray(np.linalg.lstsq(A, b, rcond=None)[0], dtype=float)
        done = np.max(np.abs(new - p_fm)) < 1e-12
        p_fm = new
        if done:
            break
    R_fm = np.eye(3)
    if data.R is not None:
        R_fm = nearest_rotation(np.sum(np.swapaxes(T_tb[:3, :3] @ T_bf[:, :3, :3], 1, 2) @ data.R, axis=0))
    return T_tb, make_transform(R_fm, p_fm)


# --- fits ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TrackerFit:
    """One model fitted to tracker data.

    Attributes:
        model: a name of :data:`TRACKER_MODELS`.
        T_tracker_base: the robot's base in the tracker's frame.
        T_flange_marker: the marker on the flange (3-D marker: identity rotation, position only).
        arm: the arm fit (corrections ``(nq, 6)``, their posterior, identifiability, noise levels
            ``position`` metres and ``orientation`` radians).
        position_residuals: ``(N, 3)`` predicted − measured (metres, tracker frame).
        orientation_residuals: ``(N, 3)`` (radians) or ``None``.
    """

    model: str
    T_tracker_base: FloatArray
    T_flange_marker: FloatArray
    arm: ArmFit
    position_residuals: FloatArray
    orientation_residuals: FloatArray | None

    @property
    def corrections(self) -> FloatArray:
        return self.arm.corrections

    @property
    def parameters(self) -> list[str]:
        """Names of the estimated corrections (the model's base set)."""
        return self.arm.selection.names

    @property
    def sigma(self) -> dict[str, float]:
        return self.arm.sigma

    def robot(self, nominal: Robot) -> Robot:
        return corrected_robot(nominal, self.corrections)

    def predict(self, data: TrackerData) -> tuple[FloatArray, FloatArray]:
        """``(p (N, 3), R (N, 3, 3))`` the marker's predicted pose in the tracker's frame at ``data``'s postures."""
        T = self.T_tracker_base @ self.robot(data.robot).fk(data.flange, data.Q) @ self.T_flange_marker
        return T[:, :3, 3], T[:, :3, :3]


def model_selection(robot: Robot, model: str, flange: str) -> ParameterSelection:
    """The corrections a model may estimate (before the base set): none (``frames``), each joint's
    zero (``offsets``: the component along a revolute joint's rotation axis or a prismatic one's
    slide, which must be a coordinate axis of the joint's frame), or all (``joints``)."""
    if model not in TRACKER_MODELS:
        raise InputError(f"unknown model {model!r}; expected one of {', '.join(TRACKER_MODELS)}")
    chain = ParameterSelection.chain(robot, flange)
    if model == "joints":
        return chain
    free = np.zeros_like(chain.free)
    if model == "offsets":
        for j, name in enumerate(robot.joint_names):
            if not chain.free[j, 0]:
                continue
            axis = np.abs(robot.joint_axis(name))
            k = int(np.argmax(axis))
            if axis[k] < 1 - 1e-12:
                raise InputError(f"joint {name!r}: its axis is not a coordinate axis; use the 'joints' model")
            free[j, k + (0 if robot.in_metres[j] else 3)] = True
    return ParameterSelection(chain.joint_names, free)


def select_parameters(data: TrackerData, model: str, accuracy: RobotAccuracy | None) -> ParameterSelection:
    """The model's corrections the data can see (:meth:`ParameterSelection.base_set` at the
    starting frames, the frames free; columns in prior units, or metres and radians without a prior)."""
    selection = model_selection(data.robot, model, data.flange)
    if not selection.size:
        return selection
    residuals = TrackerResiduals(data, *start_frames(data))
    evaluation = residuals.evaluate(data.robot, np.zeros(residuals.ny))
    w = 1.0 / np.array([START_SIGMA[g] for g in residuals.groups])[evaluation.group]
    scale = prior_sd(data.robot, accuracy) if accuracy is not None else np.ones(6 * data.robot.nq)
    return selection.base_set(evaluation.J_c * w[:, None], evaluation.J_y * w[:, None], scale)


def fit_tracker(
    data: TrackerData,
    model: str = "frames",
    accuracy: RobotAccuracy | None = TRACKER_ACCURACY,
    *,
    selection: ParameterSelection | None = None,
    estimate_noise: bool = True,
    prior: str = "stated",
) -> TrackerFit:
    """Fit ``model`` (:data:`TRACKER_MODELS`) to ``data`` (module docstring) with
    :func:`~brachycal.calibration.robot.arm_fit.fit_arm`.

    ``selection``: :func:`select_parameters`' result, reused across folds (default: computed).
    ``accuracy`` ``None``: no prior (plain least squares on the base set). ``estimate_noise``
    false: the levels are held at :data:`START_SIGMA` (exact data, whose levels are rounding).
    ``prior`` ``"evidence"``: the prior is :func:`tracker_evidence_prior` of ``data`` searched from
    ``accuracy`` (recorded in the fit's ``arm.accuracy``).

    Raises:
        DegenerateDataError: too few postures for the frames and noise levels.
        InputError: an unknown ``prior``, or ``"evidence"`` without an accuracy to start from.
    """
    chosen = selection if selection is not None else select_parameters(data, model, accuracy)
    if prior == "evidence":
        if accuracy is None:
            raise InputError("a prior chosen by the evidence needs a stated accuracy to start from")
        if chosen.size:  # without corrections the prior does not enter
            accuracy = tracker_evidence_prior(data, model, accuracy, selection=chosen).accuracy
    elif prior not in TRACKER_PRIORS:
        raise InputError(f"unknown prior {prior!r} ({', '.join(TRACKER_PRIORS)})")
    residuals = TrackerResiduals(data, *start_frames(data))
    n_rows = len(data.Q) * len(residuals.groups) * 3
    if n_rows <= residuals.ny:
        raise DegenerateDataError(
            f"tracker fit: {len(data.Q)} postures give {n_rows} measurements for {residuals.ny} frame unknowns"
        )
    arm = fit_arm(
        data.robot,
        residuals,
        np.zeros(residuals.ny),
        chosen,
        {g: START_SIGMA[g] for g in residuals.groups},
        accuracy,
        estimate_noise=residuals.groups if estimate_noise else (),
    )
    T_tb, T_fm = residuals.frames(arm.y)
    r = arm.residuals.r
    N = len(data.Q)
    r_o = r[3 * N :].reshape(N, 3) if data.six_d else None
    return TrackerFit(model, T_tb, T_fm, arm, r[: 3 * N].reshape(N, 3), r_o)


def tracker_evidence_prior(
    data: TrackerData,
    model: str,
    start: RobotAccuracy = TRACKER_ACCURACY,
    *,
    selection: ParameterSelection | None = None,
) -> EvidenceChoice:
    """The per-joint translation and rotation SDs of the corrections that maximise the evidence of
    ``data``'s postures under ``model`` (type-II maximum likelihood;
    :func:`~brachycal.calibration.robot.evidence.evidence_search` from ``start``, the noise levels
    re-estimated in each fit, the free corrections ``selection``: default :func:`select_parameters`
    at ``start``). A model without corrections (``frames``) has nothing to choose: ``start`` is
    returned. Only ``data`` enter: a fold's choice is its training postures' own.

    Raises:
        DegenerateDataError: the postures do not determine the unknowns at ``start``.
    """
    chosen = selection if selection is not None else select_parameters(data, model, start)

    def log_evidence(accuracy: RobotAccuracy, _: tuple[float, ...]) -> float:
        return fit_tracker(data, model, accuracy, selection=chosen).arm.log_evidence

    if not chosen.size:
        return EvidenceChoice(start, (), log_evidence(start, ()), 1)
    return evidence_search(
        log_evidence, start, source="chosen by the evidence of the training postures", data="the postures"
    )


def leave_one_out(
    data: TrackerData,
    model: str,
    accuracy: RobotAccuracy | None = TRACKER_ACCURACY,
    *,
    prior: str = "stated",
    progress: Callable[[int], None] | None = None,
) -> tuple[FloatArray, FloatArray | None]:
    """``(N, 3)`` position errors (metres) and, 6-D, ``(N, 3)`` orientation errors (radians) of
    each posture predicted by a fit of ``model`` made without it (the parameter selection is
    made once on all postures: it is structural, not a fit to the values). ``prior``
    ``"evidence"``: each fold's prior is chosen by that fold's own postures (:func:`fit_tracker`),
    never by the posture it predicts. ``progress``: called with 1 after each fold."""
    selection = select_parameters(data, model, accuracy)
    N = len(data.Q)
    e_p = np.zeros((N, 3))
    e_o = np.zeros((N, 3)) if data.six_d else None
    for i in range(N):
        keep = np.arange(N) != i
        fit = fit_tracker(data.subset(keep), model, accuracy, selection=selection, prior=prior)
        held = data.subset(~keep)
        p, R = fit.predict(held)
        e_p[i] = p[0] - held.p[0]
        if e_o is not None and held.R is not None:
            e_o[i] = _log(R @ np.swapaxes(held.R, 1, 2))[0]
        if progress is not None:
            progress(1)
    return e_p, e_o


@dataclass(frozen=True)
class ModelScore:
    """One model's figures: leave-one-out (headline) and training, per coordinate (mm, deg).

    ``vs_chosen``: the paired comparison with the model chosen before it (mean difference of the
    held-out postures' squared position errors per coordinate, mm², and its standard error);
    ``None`` for the first model. ``prior``: the prior of its fit on all postures (with
    ``prior="evidence"``, each leave-one-out fold chose its own)."""

    model: str
    parameters: int
    loo_position_mm: float
    training_position_mm: float
    loo_orientation_deg: float | None
    training_orientation_deg: float | None
    loo_errors_m: FloatArray = field(repr=False)
    vs_chosen: tuple[float, float] | None = None
    prior: RobotAccuracy | None = None


@dataclass(frozen=True)
class TrackerIdentification:
    """The models' scores, the supported model and its fit, and why it was chosen."""

    scores: tuple[ModelScore, ...]
    chosen: str
    reason: str
    fit: TrackerFit
    data: TrackerData
    accuracy: RobotAccuracy | None
    prior: str = "stated"

    def as_json(self) -> dict[str, object]:
        """The figures, the choice, the frames and the chosen model's corrections (mm, deg, SI matrices)."""
        fit = self.fit
        corrections = {
            name: dict(zip(COMPONENTS, map(float, c), strict=True))
            for name, c in zip(self.data.robot.joint_names, fit.corrections, strict=True)
            if np.any(c != 0.0)
        }
        noise = {"position_mm": fit.sigma["position"] * 1e3}
        if "orientation" in fit.sigma:
            noise["orientation_deg"] = float(np.degrees(fit.sigma["orientation"]))
        return {
            "protocol": "tracker",
            "postures": len(self.data.Q),
            "marker": "6-D" if self.data.six_d else "3-D",
            "flange": self.data.flange,
            "models": {
                s.model: {
                    "parameters": s.parameters,
                    "loo_position_mm_per_coordinate": s.loo_position_mm,
                    "training_position_mm_per_coordinate": s.training_position_mm,
                    "loo_orientation_deg": s.loo_orientation_deg,
                    "training_orientation_deg": s.training_orientation_deg,
                    "loo_change_vs_previous_choice_mm2": None if s.vs_chosen is None else list(s.vs_chosen),
                    "prior": None if s.prior is None else s.prior.as_json(),
                }
                for s in self.scores
            },
            "chosen": self.chosen,
            "reason": self.reason,
            "T_tracker_base": fit.T_tracker_base.tolist(),
            "T_flange_marker": fit.T_flange_marker.tolist(),
            "noise": noise,
            "estimated": fit.parameters,
            "parameterisation": "per joint origin: T_parent_joint <- T_parent_joint @ T(exp(w), v); metres, radians",
            "corrections": corrections,
            "prior": None if fit.arm.accuracy is None else fit.arm.accuracy.as_json(),
            "prior_rule": self.prior,
            "log_evidence": fit.arm.log_evidence,
        }

    def summary(self) -> list[str]:
        lines = []
        for s in self.scores:
            o = (
                f", orientation {s.loo_orientation_deg:.3f} deg LOO / {s.training_orientation_deg:.3f} deg training"
                if s.loo_orientation_deg is not None
                else ""
            )
            p = (
                f"; prior {s.prior.translation_sd_m * 1e3:.3g} mm / {np.degrees(s.prior.rotation_sd_rad):.3g} deg"
                if self.prior == "evidence" and s.prior is not None and s.parameters > (12 if self.data.six_d else 9)
                else ""
            )
            lines.append(
                f"{s.model:8s} {s.parameters:3d} params: position {s.loo_position_mm:.3f} mm LOO / "
                f"{s.training_position_mm:.3f} mm training per coordinate{o}{p}"
            )
        lines.append(f"chosen: {self.chosen} ({self.reason})")
        return lines


def _per_coordinate_mm(e: FloatArray) -> float:
    return float(np.sqrt(np.mean(e**2)) * 1e3)


def _deg(e: FloatArray | None) -> float | None:
    return None if e is None else float(np.degrees(np.sqrt(np.mean(e**2))))


def _scored_models(models: tuple[str, ...], forced: str | None) -> tuple[str, ...]:
    """The models :func:`identify_from_tracker` scores: ``models``, or with ``forced`` the frames and it."""
    if forced is None:
        return models
    if forced not in TRACKER_MODELS:
        raise InputError(f"unknown model {forced!r}; expected one of {', '.join(TRACKER_MODELS)}")
    return ("frames",) if forced == "frames" else ("frames", forced)


def tracker_fits(postures: int, models: tuple[str, ...] = TRACKER_MODELS, *, model: str | None = None) -> int:
    """The units of work :func:`identify_from_tracker` reports to its ``progress`` for ``postures``
    postures: per model scored, its fit on all postures and one leave-one-out fold per posture
    (with ``prior="evidence"`` each of them an evidence search)."""
    return len(_scored_models(models, model)) * (postures + 1)


def identify_from_tracker(
    data: TrackerData,
    accuracy: RobotAccuracy | None = TRACKER_ACCURACY,
    models: tuple[str, ...] = TRACKER_MODELS,
    *,
    model: str | None = None,
    prior: str = "stated",
    progress: Callable[[int], None] | None = None,
) -> TrackerIdentification:
    """Score ``models`` (smallest first) by leave-one-out and return the supported one (module
    docstring): each richer model replaces the chosen one only if its held-out mean squared
    position error is lower by more than the paired differences' standard error. ``model``:
    return that one whatever the scores say (it is scored too, after the frames alone).
    ``prior``: ``"stated"`` (``accuracy``) or ``"evidence"`` (per model, :func:`tracker_evidence_prior`
    searched from ``accuracy``: on all postures for the returned fit, on each fold's own postures
    for its held-out error). ``progress``: called with 1 after each model's fit on all postures
    and after each of its leave-one-out folds (:func:`tracker_fits` of them in all)."""
    if prior not in TRACKER_PRIORS:
        raise InputError(f"unknown prior {prior!r} ({', '.join(TRACKER_PRIORS)})")
    forced = model
    models = _scored_models(models, forced)
    scores: list[ModelScore] = []
    fits: dict[str, TrackerFit] = {}
    chosen, chosen_sq = "", np.zeros(0)
    reasons: list[str] = []
    for name in models:
        fit = fit_tracker(data, name, accuracy, prior=prior)
        if progress is not None:
            progress(1)
        e_p, e_o = leave_one_out(data, name, accuracy, prior=prior, progress=progress)
        fits[name] = fit
        sq = np.sum(e_p**2, axis=1) / 3 * 1e6  # mm² per coordinate, per held-out posture
        versus = None
        if not chosen:
            chosen, chosen_sq = name, sq
            reasons.append(f"{name}: the smallest model")
        else:
            d = sq - chosen_sq
            mean, se = float(np.mean(d)), float(np.std(d, ddof=1) / np.sqrt(len(d)))
            versus = (mean, se)
            if mean < -se:
                reasons.append(f"{name} beats {chosen} by {-mean:.3g} ± {se:.3g} mm² (LOO)")
                chosen, chosen_sq = name, sq
            else:
                reasons.append(
                    f"{name} not supported: LOO change {mean:+.3g} ± {se:.3g} mm² vs {chosen}, "
                    "not better by more than its standard error"
                )
        scores.append(
            ModelScore(
                name,
                (12 if data.six_d else 9) + len(fit.parameters),
                _per_coordinate_mm(e_p),
                _per_coordinate_mm(fit.position_residuals),
                _deg(e_o),
                _deg(fit.orientation_residuals),
                e_p,
                versus,
                fit.arm.accuracy,
            )
        )
    if forced is not None and forced != chosen:
        reasons.append(f"{forced} returned as asked")
        chosen = forced
    return TrackerIdentification(tuple(scores), chosen, "; ".join(reasons), fits[chosen], data, accuracy, prior)


def identify_tracker_file(
    robot: Robot,
    table: str | os.PathLike[str],
    columns: str | os.PathLike[str],
    accuracy: RobotAccuracy | None = TRACKER_ACCURACY,
    *,
    flange: str | None = None,
    model: str | None = None,
    prior: str = "stated",
    progress: Callable[[int], None] | None = None,
) -> TrackerIdentification:
    """:func:`identify_from_tracker` of a tracker table file read with its column spec file
    (:func:`~brachycal.data.formats.tracker_table.read_tracker_table`)."""
    data = tracker_data(robot, read_tracker_table(table, read_tracker_columns(columns)), flange)
    return identify_from_tracker(data, accuracy, model=model, prior=prior, progress=progress)
