"""The dual-arm session as a :class:`~brachycal.calibration.robot.arm_fit.ResidualModel`: the
whole chain's residuals (touches, axes moves, image samples; :func:`chain_residuals`) with the
chain's own parameters (the tools, the image calibration) as the protocol's unknowns ``y``, and
the joint-origin Jacobian of :func:`robot_jacobian_at`. With it :func:`fit_arm` identifies the
dual-arm rig as it does an arm from touches or a tracker.

:func:`fit_session` is the session's robot identification (the estimate of
:func:`~brachycal.calibration.robot.identification.identify_robot`, which adds the chain's checked
fit on the corrected robot and the joint posterior in the chain's terms):

1. the chain on the nominal robot (:func:`chain_start`: its robust and final stages): the start of
   ``y``, the groups' starting noise levels and the outliers it flags, left out;
2. :func:`fit_arm` with every joint origin free and the stated accuracy its prior, the three
   groups' noise levels re-estimated between rounds by the chain's rule (:attr:`SessionResiduals.noise_rules`:
   a group with too few residual degrees of freedom, usually the axes moves, takes the touches'
   level, or the chain's starting level; none below the resolution);
3. the outliers flagged again by the chain's own fit on the corrected robot (:func:`fit_chain`);
   where they differ, :func:`fit_arm` again on those samples.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from brachycal.calibration.chain import (
    GROUPS,
    INITIAL_SIGMA,
    MIN_NOISE_DOF,
    POOLED_WITH,
    RESOLUTION_M,
    ChainData,
    ChainProblem,
    NoiseLevel,
    ParameterLayout,
    assumed_level,
    chain_jacobian,
    chain_residuals,
    final_stage,
    fit_chain,
    image_residuals,
    measured_level,
    robot_jacobian_at,
    robust_stage,
)
from brachycal.calibration.robot.arm_fit import ArmFit, Evaluation, NoiseRule, ParameterSelection, fit_arm, prior_sd
from brachycal.calibration.robot_accuracy import RobotAccuracy
from brachycal.calibration.sequential.method import SequentialResult
from brachycal.data.session import Session
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray

#: Noise groups: the chain's (touches, axes moves, image samples), metres per coordinate.
SESSION_GROUPS = GROUPS
#: A step in a chain parameter below this (metres, radians, relative spacing) is nothing worth noticing.
CHAIN_STEP = 1e-3
#: Noise rounds of the fit after the outliers were flagged again (from the first fit's levels,
#: already near their fixed point).
REFLAG_ROUNDS = 2


@dataclass(frozen=True)
class ChainStart:
    """The whole chain solved on the nominal robot without its covariance and conditioning checks:
    the start of the identification (a worn robot's scatter can leave a rotation too uncertain
    for the chain alone to report on, which identification then resolves; the final fit on the
    corrected robot is checked in full)."""

    layout: ParameterLayout
    base: dict[str, FloatArray]
    x: FloatArray
    sigma: dict[str, float]
    outliers: np.ndarray

    def image_residuals(self, session: Session, robot: Robot) -> FloatArray:
        """``(N, 3)`` every sample's image residual (metres) at this estimate."""
        T_ER_Ntip, T_EL_Ptip, T_Ptip_I, _, spacing = self.layout.unpack(self.x, self.base, session.spacing_m)
        return image_residuals(ChainData.of(session, robot), T_ER_Ntip, T_EL_Ptip @ T_Ptip_I, spacing)


def chain_start(
    session: Session, robot: Robot, initial: SequentialResult, model: str, use: np.ndarray, rounds: int
) -> ChainStart:
    """:func:`fit_chain`'s robust and final stages on ``robot`` (samples ``use``), unchecked."""
    problem, x = ChainProblem.start(session, robot, initial, ParameterLayout(model))
    x, sigma, outliers = robust_stage(problem, x, dict(INITIAL_SIGMA), use, rounds)
    final = final_stage(problem, x, sigma, use, outliers)
    return ChainStart(problem.layout, problem.base, final.x, final.sigma, final.outliers)


@dataclass(frozen=True)
class SessionResiduals:
    """The session's residuals (metres, unnormalised) on a robot at the chain parameters ``y``.

    Attributes:
        session: the recorded data.
        layout: the chain's parameters (the image model's).
        base: the layout's linearisation point (``y`` is a step from it).
        keep: ``(N,)`` the image samples in the fit.
        size: the number of chain parameters.
    """

    session: Session
    layout: ParameterLayout
    base: dict[str, FloatArray]
    keep: np.ndarray
    size: int

    @property
    def groups(self) -> tuple[str, ...]:
        return SESSION_GROUPS

    @property
    def noise_rules(self) -> Mapping[str, NoiseRule]:
        """The chain's rule (:func:`~brachycal.calibration.chain.noise_levels`): below
        :data:`~brachycal.calibration.chain.MIN_NOISE_DOF` residual degrees of freedom a group takes
        the level of the group it is pooled with (the axes moves: the touches'), else its
        :data:`~brachycal.calibration.chain.INITIAL_SIGMA`; no level below
        :data:`~brachycal.calibration.chain.RESOLUTION_M`."""
        return {g: NoiseRule(POOLED_WITH.get(g), RESOLUTION_M, INITIAL_SIGMA[g]) for g in SESSION_GROUPS}

    def y_scale(self) -> FloatArray:
        return np.full(self.size, CHAIN_STEP)

    def evaluate(self, robot: Robot, y: FloatArray) -> Evaluation:
        data = ChainData.of(self.session, robot)
        unit = dict.fromkeys(SESSION_GROUPS, 1.0)
        r = chain_residuals(y, self.layout, data, self.base, unit, self.keep)
        J_y = chain_jacobian(y, self.layout, data, self.base, unit, self.keep)
        J_c = robot_jacobian_at(self.session, robot, self.layout, y, self.base, unit, self.keep)
        group = np.zeros(len(r), dtype=int)
        for g, rows in data.group_rows(int(self.keep.sum())).items():
            group[rows] = SESSION_GROUPS.index(g)
        return Evaluation(r, J_c, J_y, group)


@dataclass(frozen=True)
class SessionFit:
    """The dual-arm rig identified from its session (module docstring).

    Attributes:
        residuals: the protocol on the samples fitted (``residuals.keep``).
        arm: :func:`fit_arm`'s estimate: the corrections, the chain parameters ``y``, the noise
            levels, the posterior of (corrections, ``y``).
        outliers: ``(N,)`` the samples the chain flags on the corrected robot (left out).
    """

    residuals: SessionResiduals
    arm: ArmFit
    outliers: np.ndarray

    def noise(self) -> dict[str, NoiseLevel]:
        """The groups' levels with their degrees of freedom and sources, as the chain reports them
        (:class:`~brachycal.calibration.chain.NoiseLevel`): those estimated from their own rows
        first."""
        dof = self.arm.noise_dof
        measured = {g: measured_level(self.arm.sigma[g], dof[g]) for g in SESSION_GROUPS if dof[g] >= MIN_NOISE_DOF}
        return measured | {g: assumed_level(g, measured, dof[g]) for g in SESSION_GROUPS if g not in measured}

    def posterior(self, nominal: Robot) -> FloatArray:
        """``(P + 6 nq, P + 6 nq)`` the joint posterior of (chain parameters, corrections in prior
        units: each over its prior SD, :func:`prior_sd`)."""
        assert self.arm.accuracy is not None  # fit_session states one
        n, p = self.arm.selection.size, self.residuals.size
        order = np.concatenate([np.arange(n, n + p), np.arange(n)])
        units = np.concatenate([np.ones(p), 1.0 / prior_sd(nominal, self.arm.accuracy)[self.arm.selection.index]])
        return self.arm.covariance[np.ix_(order, order)] * np.outer(units, units)

    def normalised_jacobian(self, nominal: Robot) -> FloatArray:
        """``(M, P + 6 nq)`` the data rows of the normalised problem at the estimate: ``[J_y, J_c · s] / σ``
        (``s`` the prior SD, σ each row's noise level), ``J_c`` the protocol's own on the corrected
        robot (:func:`robot_jacobian_at`: per motion composed on each corrected origin, the
        chain's robot terms)."""
        assert self.arm.accuracy is not None  # fit_session states one
        evaluation = self.residuals.evaluate(self.arm.robot(nominal), self.arm.y)
        w = 1.0 / np.array([self.arm.sigma[g] for g in SESSION_GROUPS])[evaluation.group]
        scale = prior_sd(nominal, self.arm.accuracy)[self.arm.selection.index]
        return np.hstack([evaluation.J_y, evaluation.J_c[:, self.arm.selection.index] * scale]) * w[:, None]


def fit_session(
    session: Session,
    robot: Robot,
    initial: SequentialResult,
    model: str,
    accuracy: RobotAccuracy,
    *,
    samples: np.ndarray | None = None,
    rounds: int = 2,
) -> SessionFit:
    """The dual-arm rig identified by :func:`fit_arm` from its session (module docstring): every
    joint origin free with ``accuracy`` its prior, the chain (image ``model``) its unknowns.

    Args:
        samples: ``(N,)`` bool mask of the image samples to use (cross-validation; default all).
        rounds: robust solves of the chain's fits (:func:`fit_chain`'s).

    Raises:
        DegenerateDataError: the session does not determine the chain, on the nominal or the
            corrected robot.
    """
    use = np.ones(len(session.uv_px), dtype=bool) if samples is None else np.asarray(samples, dtype=bool)
    first = chain_start(session, robot, initial, model, use, rounds)
    residuals = SessionResiduals(session, first.layout, first.base, use & ~first.outliers, len(first.x))
    selection = ParameterSelection(tuple(robot.joint_names), np.ones((robot.nq, 6), dtype=bool))
    arm = fit_arm(robot, residuals, first.x.copy(), selection, first.sigma, accuracy, estimate_noise=SESSION_GROUPS)
    # The chain on the corrected robot: its outlier flags (and its conditioning checks, in full).
    flags = fit_chain(session, arm.robot(robot), initial, model, samples=use, rounds=rounds, robot_accuracy=None)
    keep = use & ~flags.outliers
    if not np.array_equal(keep, residuals.keep):  # other flags: the MAP problem again on those samples
        residuals = replace(residuals, keep=keep)
        arm = fit_arm(
            robot, residuals, arm.y, selection, arm.sigma, accuracy, estimate_noise=SESSION_GROUPS, rounds=REFLAG_ROUNDS
        )
    return SessionFit(residuals, arm, flags.outliers)
