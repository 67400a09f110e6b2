"""Arm identification core: the joint-origin corrections of any serial arm, fitted to any protocol.

A protocol (touches of fixed points, a tracker's 3-D or 6-D measurements, the dual-arm session)
supplies a :class:`ResidualModel`: its residuals (metres) on a robot, their Jacobian with respect
to every joint-origin correction (joint-major ``(v, ω)``, :func:`joint_twists`' order) and to its
own unknowns ``y`` (tool points, fixed points, a tracker's pose), and a noise group per row. This
module does the rest, the same for every protocol:

* :class:`ParameterSelection`: which corrections are free: :meth:`~ParameterSelection.chain`, the
  joints to the flange; :meth:`~ParameterSelection.base_set`, only what the data see once ``y`` is
  free (pivoted QR; FIGAROH's base parameters).
* :func:`flange_points`: a flange-fixed point's world position and its Jacobian (analytic, from
  :func:`joint_twists`).
* :func:`fit_arm`: the MAP fit ``min ‖r/σ‖² + ‖c/s‖²`` (``s`` the stated accuracy) by
  Levenberg–Marquardt, the free groups' noise levels re-estimated between rounds (a protocol may
  declare a :class:`NoiseRule` per group: too few degrees of freedom of its own, and it takes
  another group's level), its posterior covariance and the identifiability
  (:func:`identifiability`) of all ``6 nq`` corrections.
* :func:`gravity_moments`, :func:`deflection_columns`: joint compliance under gravity (each
  joint's frame turning by ``k · m`` under its gravity moment ``m``), fitted as protocol unknowns.

Corrections are :func:`corrected_robot`'s: ``T_parent_joint ← T_parent_joint @ T(exp ω, v)``.

Design: ``docs/design/robot_identification.md``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np
import pinocchio as pin
import scipy.linalg

from brachycal.calibration.chain.noise import MIN_NOISE_DOF
from brachycal.calibration.chain.robot_terms import joint_twists, motion_rows, point_motion
from brachycal.calibration.robot.identifiability import COMPONENTS, Identifiability, identifiability
from brachycal.calibration.robot_accuracy import RobotAccuracy
from brachycal.errors import DegenerateDataError, InputError
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray, left_jacobian, make_transform, rotation

#: Base set: a correction is kept when its column, prior-scaled and projected off the protocol's
#: unknowns, adds at least this fraction of the largest pivot (pivoted QR). Exactly absorbed
#: columns fall to rounding (~1e-15 relative); weakly seen ones stay above 1e-6 on real protocols.
BASE_RCOND = 1e-8
#: Gauss–Newton: stop when the largest step is below this in prior units / own scale.
STEP_TOLERANCE = 1e-7
#: Gauss–Newton: stop when a step lowers the cost by less than this fraction (rounding level:
#: the cost's own evaluation is good to ~1e-14 relative).
COST_TOLERANCE = 1e-12
#: Gauss–Newton iterations per noise round at most.
ITERATIONS = 50
#: Noise rounds: each re-estimates the free groups' levels from the previous round's residuals.
ROUNDS = 4


def corrected_robot(nominal: Robot, corrections: FloatArray) -> Robot:
    """``nominal`` with joint ``j``'s origin moved by ``corrections[j] = (v, ω)`` (metres, radians).

    ``T_parent_joint ← T_parent_joint @ T(exp(ω), v)`` for each one-axis joint, in
    ``nominal.joint_names`` order; ``corrections`` is ``(nq, 6)``. Tool frames are untouched.
    """
    corrections = np.asarray(corrections, dtype=float)
    if corrections.shape != (nominal.nq, 6) or not np.all(np.isfinite(corrections)):
        raise InputError(f"robot corrections must be finite with shape ({nominal.nq}, 6), got {corrections.shape}")
    origins = {
        name: nominal.joint_origin(name) @ make_transform(rotation(c[3:]), c[:3])
        for name, c in zip(nominal.joint_names, corrections, strict=True)
        if np.any(c != 0.0)
    }
    return nominal.with_joint_origins(origins) if origins else nominal


def prior_sd(robot: Robot, accuracy: RobotAccuracy) -> FloatArray:
    """``(6 nq,)`` prior SD of each correction: the stated translation and rotation SDs; the rotation
    about a joint's axis also carries its zero offset (variance doubled, as the consider covariance)."""
    return np.sqrt(np.diag(accuracy.covariance(robot)))


@dataclass(frozen=True)
class ParameterSelection:
    """Which joint-origin corrections are free.

    Attributes:
        joint_names: the robot's joints (configuration order).
        free: ``(nq, 6)`` bool, per joint its free components ``(vx, vy, vz, wx, wy, wz)``.
    """

    joint_names: tuple[str, ...]
    free: np.ndarray

    @classmethod
    def chain(cls, robot: Robot, flange: str) -> ParameterSelection:
        """All six components of every joint between the base and ``flange``."""
        model = robot.model
        support = set(model.supports[model.frames[robot.frame_id(flange)].parentJoint])
        on_chain = np.array([model.getJointId(name) in support for name in robot.joint_names])
        return cls(tuple(robot.joint_names), np.repeat(on_chain[:, None], 6, axis=1))

    @property
    def size(self) -> int:
        return int(self.free.sum())

    @property
    def index(self) -> np.ndarray:
        """Flat indices (joint-major, ``6 j + component``) of the free corrections."""
        return np.flatnonzero(self.free.reshape(-1))

    @property
    def names(self) -> list[str]:
        """``"joint.component"`` of each free correction."""
        return [f"{self.joint_names[k // 6]}.{COMPONENTS[k % 6]}" for k in self.index]

    def expand(self, x: FloatArray) -> FloatArray:
        """``(nq, 6)`` corrections: ``x`` ``(size,)`` at the free components, zero elsewhere."""
        out = np.zeros(6 * len(self.joint_names))
        out[self.index] = x
        return out.reshape(-1, 6)

    def base_set(
        self, J_c: FloatArray, J_y: FloatArray, scale: FloatArray, rcond: float = BASE_RCOND
    ) -> ParameterSelection:
        """The free corrections the data see at all: those of this selection whose columns of
        ``J_c`` ``(M, 6 nq)`` (× ``scale``, the prior SD), projected off the span of ``J_y`` ``(M, ny)``,
        a pivoted QR ranks independent (pivot above ``rcond`` of the largest)."""
        index = self.index
        if J_y.shape[1]:
            Q, _ = np.linalg.qr(J_y)
            projected = J_c[:, index] * scale[index] - Q @ (Q.T @ (J_c[:, index] * scale[index]))
        else:
            projected = J_c[:, index] * scale[index]
        _, R, pivots = scipy.linalg.qr(projected, mode="economic", pivoting=True)
        d = np.abs(np.diag(R))
        rank = int(np.sum(d > d[0] * rcond)) if d.size and d[0] > 0 else 0
        free = np.zeros(6 * len(self.joint_names), dtype=bool)
        free[index[pivots[:rank]]] = True
        return ParameterSelection(self.joint_names, free.reshape(-1, 6))


@dataclass(frozen=True)
class FlangePoints:
    """Points fixed to a flange, at many configurations.

    Attributes:
        p: ``(N, 3)`` world positions (metres, base frame).
        R: ``(N, 3, 3)`` the flange's rotations: ``∂p/∂p_flange``.
        J_c: ``(N, 3, 6 nq)`` ``∂p/∂c`` (joint-major ``(v, ω)``).
        W: ``(N, nq, 6, 6)`` the flange's world twists per joint-origin motion (:func:`joint_twists`).
    """

    p: FloatArray
    R: FloatArray
    J_c: FloatArray
    W: FloatArray


def flange_points(robot: Robot, Q: FloatArray, flange: str, p_flange: FloatArray) -> FlangePoints:
    """The point ``p_flange`` (``(3,)`` or ``(N, 3)``, metres in ``flange``) at configurations ``Q``
    ``(N, nq)`` and its Jacobian with respect to every joint-origin correction (analytic:
    ``[I, −[p]×]`` through :func:`joint_twists`)."""
    Q = np.atleast_2d(np.asarray(Q, dtype=float))
    T = robot.fk_frames([flange], Q)[0]
    p_flange = np.broadcast_to(np.asarray(p_flange, dtype=float), (len(Q), 3))
    p = np.einsum("nab,nb->na", T[:, :3, :3], p_flange) + T[:, :3, 3]
    W = joint_twists(robot, Q, flange)
    J_c = motion_rows(point_motion(p), W).reshape(len(Q), 3, -1)
    return FlangePoints(p, T[:, :3, :3], J_c, W)


@dataclass(frozen=True)
class Evaluation:
    """A protocol's residuals at one estimate.

    Attributes:
        r: ``(M,)`` residuals (metres, or the group's own unit).
        J_c: ``(M, 6 nq)`` ``∂r/∂c``, joint-major ``(v, ω)``.
        J_y: ``(M, ny)`` ``∂r/∂y``.
        group: ``(M,)`` int, each row's noise group (an index into :attr:`ResidualModel.groups`).
    """

    r: FloatArray
    J_c: FloatArray
    J_y: FloatArray
    group: np.ndarray


class ResidualModel(Protocol):
    """A protocol's residuals: ``groups`` names the noise groups; ``evaluate`` gives the
    residuals on ``robot`` (the corrected robot) at the protocol's unknowns ``y``; ``y_scale``
    the size of a step in each unknown worth noticing (Gauss–Newton's stopping test).

    A protocol may also state how some groups' levels are estimated (:class:`DeclaresNoiseRules`)."""

    @property
    def groups(self) -> tuple[str, ...]: ...

    def evaluate(self, robot: Robot, y: FloatArray) -> Evaluation: ...

    def y_scale(self) -> FloatArray: ...


@dataclass(frozen=True)
class NoiseRule:
    """How :func:`fit_arm` re-estimates one group's noise level between rounds, beyond its default
    (the group's residual sum of squares over its residual degrees of freedom ``ν``, its rows minus
    their leverages in the regularised problem).

    With a rule, a group whose own ``ν`` is below :data:`~brachycal.calibration.chain.MIN_NOISE_DOF`
    (its level's relative SD, ``1/√(2ν)``, above 25 %) does not estimate its own level: it takes the
    level of the group ``pooled_with`` (that group's estimate from its own rows: the two measure
    alike and that one has the rows), or ``assumed`` when there is no such group or that group has
    too few degrees of freedom too. A level estimated below ``floor`` (the measurement's
    resolution, the group's unit) is taken at ``floor``.

    Attributes:
        pooled_with: the group whose level this one takes when its own degrees of freedom are too few.
        floor: the lowest level the group is given (its unit; 0: none).
        assumed: the level it takes when neither it nor ``pooled_with`` has enough degrees of
            freedom (its unit; ``None``: the level it started with).
    """

    pooled_with: str | None = None
    floor: float = 0.0
    assumed: float | None = None


@runtime_checkable
class DeclaresNoiseRules(Protocol):
    """A :class:`ResidualModel` that states a :class:`NoiseRule` for some of its groups (by name;
    the others follow the default rule)."""

    @property
    def noise_rules(self) -> Mapping[str, NoiseRule]: ...


@dataclass(frozen=True)
class ArmFit:
    """The identified arm.

    Attributes:
        corrections: ``(nq, 6)`` per joint ``(v, ω)`` (metres, radians), :func:`corrected_robot`'s.
        joint_names: the joints, in order.
        selection: the free corrections.
        y: the protocol's unknowns at the estimate.
        sigma: each group's noise level (estimated, or as given when held).
        covariance: ``(size + ny, size + ny)`` posterior covariance of (free corrections, ``y``),
            SI units.
        identifiability: the base-set analysis of all ``6 nq`` corrections under the prior.
        accuracy: the stated accuracy used as the prior (``None``: no prior).
        residuals: the protocol's residuals at the estimate.
        iterations: Gauss–Newton steps taken in all.
        noise_dof: each estimated group's residual degrees of freedom in the last noise round (its
            rows minus their leverages; below :data:`~brachycal.calibration.chain.MIN_NOISE_DOF`, a
            group with a :class:`NoiseRule` took another group's level or its assumed one).
        log_evidence: the data's log marginal likelihood given the noise levels and priors
            (Laplace's approximation at the estimate; :func:`log_evidence`); comparable between
            fits of the same data with the same unknowns free of a prior.
    """

    corrections: FloatArray
    joint_names: tuple[str, ...]
    selection: ParameterSelection
    y: FloatArray
    sigma: dict[str, float]
    covariance: FloatArray
    identifiability: Identifiability
    accuracy: RobotAccuracy | None
    residuals: Evaluation
    iterations: int
    log_evidence: float = float("nan")
    noise_dof: dict[str, float] = field(default_factory=dict)

    def robot(self, nominal: Robot) -> Robot:
        """The corrected robot (``nominal``: the robot the fit started from)."""
        return corrected_robot(nominal, self.corrections)

    def correction_sd(self) -> FloatArray:
        """``(nq, 6)`` posterior SD of each correction (zero where it was held)."""
        out = np.zeros(6 * len(self.joint_names))
        n = self.selection.size
        out[self.selection.index] = np.sqrt(np.clip(np.diag(self.covariance)[:n], 0.0, None))
        return out.reshape(-1, 6)

    def y_covariance(self) -> FloatArray:
        """Posterior covariance of the protocol's unknowns ``y``."""
        n = self.selection.size
        return self.covariance[n:, n:]


def fit_arm(
    nominal: Robot,
    model: ResidualModel,
    y0: FloatArray,
    selection: ParameterSelection,
    sigma: Mapping[str, float],
    accuracy: RobotAccuracy | None,
    *,
    estimate_noise: Sequence[str] = (),
    y_prior_sd: FloatArray | None = None,
    rounds: int = ROUNDS,
    iterations: int = ITERATIONS,
) -> ArmFit:
    """The MAP fit of the free corrections and the protocol's unknowns (module docstring).

    Args:
        nominal: the robot's URDF.
        model: the protocol.
        y0: start of the protocol's unknowns.
        selection: the free corrections (the others stay zero).
        sigma: starting noise level of each group of ``model.groups`` (its unit).
        accuracy: the stated accuracy: the corrections' prior. ``None``: no prior (plain least
            squares; the selection must then be a base set).
        estimate_noise: groups whose levels are re-estimated from the residuals between rounds
            (the others are held as given), each by its :class:`NoiseRule` when ``model`` states
            one (:class:`DeclaresNoiseRules`).
        y_prior_sd: a zero-mean Gaussian prior's SD per protocol unknown (``inf``: none; default none).
        rounds: noise rounds, at least one (one when nothing is estimated).

    Raises:
        DegenerateDataError: the data (with the prior) do not determine the unknowns.
        InputError: a group without a noise level, or a level not positive; a noise rule naming
            a group the model does not have, or with a negative floor or a level not positive.
    """
    groups = model.groups
    for g in groups:
        if not (g in sigma and np.isfinite(sigma[g]) and sigma[g] > 0):
            raise InputError(f"noise level of {g!r} must be a positive number")
    level = np.array([float(sigma[g]) for g in groups])
    start = level.copy()
    estimated = np.array([g in estimate_noise for g in groups])
    rules = _Rules.of(model)
    index = selection.index
    full_scale = prior_sd(nominal, accuracy) if accuracy is not None else np.ones(6 * nominal.nq)
    if accuracy is not None and np.any(full_scale[index] <= 0):
        raise InputError("the stated robot accuracy is zero for a free correction: hold it, or state its accuracy")
    scale = full_scale[index]
    y_scale = np.asarray(model.y_scale(), dtype=float)
    x = np.zeros(len(index))
    y = np.asarray(y0, dtype=float).copy()
    prior = _Prior(
        accuracy is not None, np.full(len(y), np.inf) if y_prior_sd is None else np.asarray(y_prior_sd, dtype=float)
    )
    steps = 0
    dof = np.full(len(groups), np.nan)
    if rounds < 1:
        raise InputError(f"robot identification: {rounds} noise rounds; at least one is needed")
    rounds = rounds if estimated.any() else 1
    for _ in range(rounds):
        x, y, taken = _gauss_newton(nominal, model, selection, x, y, level, scale, y_scale, prior, iterations)
        steps += taken
        evaluation = _evaluate(nominal, model, selection, x, y)
        if estimated.any():
            A, _ = _system(evaluation, index, x, y, scale, level, prior)
            level, dof = _noise_levels(evaluation, A, level, start, estimated, rules)
    A, b = _system(evaluation, index, x, y, scale, level, prior)  # at the last round's estimate and levels
    posterior = _inverse(A)
    units = np.concatenate([scale, np.ones(len(y))])
    covariance = posterior * np.outer(units, units)
    report = _identifiability(nominal, evaluation, level, full_scale, len(y))
    evidence = log_evidence(A, b, level[evaluation.group], prior.y_sd, len(index) if not prior.corrections else 0)
    return ArmFit(
        selection.expand(x),
        tuple(nominal.joint_names),
        selection,
        y,
        dict(zip(groups, map(float, level), strict=True)),
        covariance,
        report,
        accuracy,
        evaluation,
        steps,
        evidence,
        {g: float(dof[k]) for k, g in enumerate(groups) if estimated[k]},
    )


def log_evidence(A: FloatArray, b: FloatArray, row_sd: FloatArray, y_sd: FloatArray, flat_corrections: int) -> float:
    """``log p(data | σ, priors)`` by Laplace's approximation at the MAP estimate (type-II likelihood).

    ``A``, ``b``: :func:`_system`'s normalised system at the estimate (data rows divided by their
    SD ``row_sd`` (metres), then the prior's rows; the corrections in prior units, so their Gaussian
    prior is ``N(0, I)``); ``y_sd``: the protocol unknowns' prior SDs (``inf``: flat, density one
    per unit). ``−½‖b‖² − Σ log σ_row − (M/2) log 2π − Σ log y_sd (finite) + (n_flat/2) log 2π −
    ½ log det AᵀA``, with ``n_flat`` the unknowns without a proper prior (flat ``y`` and
    ``flat_corrections``): it compares hyper-parameters (noise levels, prior SDs) on the same data
    with the same flat unknowns.
    """
    m = len(row_sd)
    s = np.linalg.svd(A, compute_uv=False)
    finite = np.isfinite(y_sd)
    n_flat = int(np.count_nonzero(~finite)) + flat_corrections
    return float(
        -0.5 * float(b @ b)
        - np.sum(np.log(row_sd))
        - 0.5 * m * np.log(2 * np.pi)
        - np.sum(np.log(y_sd[finite]))
        + 0.5 * n_flat * np.log(2 * np.pi)
        - np.sum(np.log(s))
    )


@dataclass(frozen=True)
class _Prior:
    """The prior rows: the corrections' (when ``corrections``), and zero-mean ones on the ``y``
    entries whose ``y_sd`` is finite."""

    corrections: bool
    y_sd: FloatArray


def _system(
    evaluation: Evaluation,
    index: np.ndarray,
    x: FloatArray,
    y: FloatArray,
    scale: FloatArray,
    level: FloatArray,
    prior: _Prior,
) -> tuple[FloatArray, FloatArray]:
    """The normalised, augmented system ``A``, ``b`` of one Gauss–Newton step over ``(x / scale, y)``:
    the data rows ``[J_c · scale, J_y] / σ``, then the prior's rows."""
    w = 1.0 / level[evaluation.group]
    rows = np.hstack([evaluation.J_c[:, index] * scale, evaluation.J_y]) * w[:, None]
    b = evaluation.r * w
    ny = evaluation.J_y.shape[1]
    if prior.corrections:
        rows = np.vstack([rows, np.hstack([np.eye(len(index)), np.zeros((len(index), ny))])])
        b = np.concatenate([b, x / scale])
    held = np.flatnonzero(np.isfinite(prior.y_sd))
    if held.size:
        y_rows = np.zeros((held.size, len(index) + ny))
        y_rows[np.arange(held.size), len(index) + held] = 1.0 / prior.y_sd[held]
        rows = np.vstack([rows, y_rows])
        b = np.concatenate([b, y[held] / prior.y_sd[held]])
    return rows, b


def _evaluate(
    nominal: Robot, model: ResidualModel, selection: ParameterSelection, x: FloatArray, y: FloatArray
) -> Evaluation:
    """The protocol at corrections ``x``, its ``J_c`` turned into the derivative with respect to the
    corrections themselves: a protocol's ``J_c`` (:func:`joint_twists`') is for a motion composed on
    the corrected origin, ``T(c) · T(δ')``, while the fit steps ``c + δc``; per joint
    ``δv' = exp(ω)ᵀ δv`` and ``δω' = J_r(ω) δω`` (SO(3)'s right Jacobian). Without it the step is off
    by ~|c| near the solution and the iterations stall instead of converging."""
    c = selection.expand(x)
    evaluation = model.evaluate(corrected_robot(nominal, c), y)
    moved = [j for j in range(len(c)) if np.any(c[j] != 0.0)]
    if not moved:
        return evaluation
    J_c = evaluation.J_c.copy()
    for j in moved:
        block = np.zeros((6, 6))
        block[:3, :3] = rotation(c[j, 3:]).T
        block[3:, 3:] = left_jacobian(-c[j, 3:])
        J_c[:, 6 * j : 6 * j + 6] = evaluation.J_c[:, 6 * j : 6 * j + 6] @ block
    return Evaluation(evaluation.r, J_c, evaluation.J_y, evaluation.group)


def _gauss_newton(
    nominal: Robot,
    model: ResidualModel,
    selection: ParameterSelection,
    x: FloatArray,
    y: FloatArray,
    level: FloatArray,
    scale: FloatArray,
    y_scale: FloatArray,
    prior: _Prior,
    iterations: int,
) -> tuple[FloatArray, FloatArray, int]:
    """Levenberg–Marquardt on the normalised system: the Gauss–Newton step, damped by ``λ`` times
    the columns' norms while a step raises the cost (a start far from the solution, a weakly
    determined combination without a prior), the damping relaxed after each accepted step."""
    index = selection.index

    def system(x: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray]:
        return _system(_evaluate(nominal, model, selection, x, y), index, x, y, scale, level, prior)

    A, b = system(x, y)
    cost = float(b @ b)
    damping = 0.0
    for k in range(iterations):
        norms = np.linalg.norm(A, axis=0)
        norms[norms == 0] = 1.0
        for _ in range(40):
            if damping:
                damped = np.vstack([A, np.diag(np.sqrt(damping) * norms)])
                step = np.linalg.lstsq(damped, -np.concatenate([b, np.zeros(len(norms))]), rcond=None)[0]
            else:
                step = np.linalg.lstsq(A, -b, rcond=None)[0]
            dx, dy = step[: len(x)] * scale, step[len(x) :]
            A_new, b_new = system(x + dx, y + dy)
            if float(b_new @ b_new) <= cost * (1 + 1e-12):
                damped_step = damping > 0
                damping = damping / 10 if damping > 1e-9 else 0.0
                break
            damping = max(damping * 10, 1e-6)
        else:
            return x, y, k
        previous = cost
        x, y, A, b, cost = x + dx, y + dy, A_new, b_new, float(b_new @ b_new)
        small = np.concatenate([np.abs(dx) / scale, np.abs(dy) / y_scale]) if len(step) else np.zeros(1)
        if not damped_step and (np.max(small) < STEP_TOLERANCE or previous - cost <= COST_TOLERANCE * previous):
            return x, y, k + 1
    return x, y, iterations


@dataclass(frozen=True)
class _Rules:
    """The groups' :class:`NoiseRule` s by index, each ``(G,)``: ``ruled`` whether a group has one,
    ``partner`` the index of its ``pooled_with`` group (−1: none), ``floor`` its floor (0: none),
    ``assumed`` its assumed level (NaN: its starting level)."""

    ruled: np.ndarray
    partner: np.ndarray
    floor: FloatArray
    assumed: FloatArray

    @classmethod
    def of(cls, model: ResidualModel) -> _Rules:
        """``model``'s rules (:class:`DeclaresNoiseRules`; none: the default rule for every group), checked."""
        groups = model.groups
        declared = dict(model.noise_rules) if isinstance(model, DeclaresNoiseRules) else {}
        for g, rule in declared.items():
            if g not in groups or rule.pooled_with not in (None, *groups) or rule.pooled_with == g:
                raise InputError(f"noise rule of {g!r}: a group pooled with another of {', '.join(groups)}")
            if not (np.isfinite(rule.floor) and rule.floor >= 0):
                raise InputError(f"noise rule of {g!r}: its floor must be a number ≥ 0")
            if rule.assumed is not None and not (np.isfinite(rule.assumed) and rule.assumed > 0):
                raise InputError(f"noise rule of {g!r}: its assumed level must be a positive number")
        rules = [declared.get(g) for g in groups]
        return cls(
            np.array([r is not None for r in rules]),
            np.array([-1 if r is None or r.pooled_with is None else groups.index(r.pooled_with) for r in rules]),
            np.array([0.0 if r is None else float(r.floor) for r in rules]),
            np.array([np.nan if r is None or r.assumed is None else float(r.assumed) for r in rules]),
        )


def _noise_levels(
    evaluation: Evaluation, A: FloatArray, level: FloatArray, start: FloatArray, estimated: np.ndarray, rules: _Rules
) -> tuple[FloatArray, FloatArray]:
    """Each estimated group's level from its residuals, its degrees of freedom reduced by the
    leverages of the regularised problem (the prior's rows take their share of the fit), and those
    degrees of freedom (NaN: not estimated). A group with a :class:`NoiseRule` and fewer than
    :data:`~brachycal.calibration.chain.MIN_NOISE_DOF` takes its ``pooled_with`` group's new level
    when that one stands on its own rows (or is held), else its assumed level (or its level at the
    start ``start``)."""
    m = len(evaluation.r)
    J = A[:m]
    h = np.einsum("ij,jk,ik->i", J, _inverse(A), J)
    out = level.copy()
    dof = np.full(len(level), np.nan)
    own = ~estimated  # levels that stand on their own: held, or estimated from the group's rows
    for g in np.flatnonzero(estimated):
        rows = evaluation.group == g
        dof[g] = rows.sum() - h[rows].sum()
        if rules.ruled[g] and dof[g] < MIN_NOISE_DOF:
            continue
        if dof[g] <= 0:
            raise DegenerateDataError(f"too few data to estimate a noise level (group {g})")
        out[g] = max(float(np.sqrt(np.sum(evaluation.r[rows] ** 2) / dof[g])), rules.floor[g])
        if not out[g] > 0:  # exact data: keep the level given
            out[g] = level[g]
        own[g] = True
    for g in np.flatnonzero(estimated & ~own):  # too few degrees of freedom, by their rule
        partner = rules.partner[g]
        if partner >= 0 and own[partner]:
            out[g] = out[partner]
        else:
            out[g] = start[g] if np.isnan(rules.assumed[g]) else rules.assumed[g]
    return out, dof


def _inverse(A: FloatArray) -> FloatArray:
    """``(AᵀA)⁻¹``, refusing a system the data and prior do not determine."""
    _, s, Vt = np.linalg.svd(A, full_matrices=False)
    if s.size == 0 or s[-1] <= s[0] * 1e-13:
        raise DegenerateDataError("robot identification: the data do not determine the unknowns")
    return (Vt.T / s**2) @ Vt


def _identifiability(
    robot: Robot, evaluation: Evaluation, level: FloatArray, scale: FloatArray, ny: int
) -> Identifiability:
    """:func:`identifiability` of all ``6 nq`` corrections (each with its prior) and the protocol's unknowns."""
    w = 1.0 / level[evaluation.group]
    J = np.hstack([evaluation.J_y, evaluation.J_c * scale]) * w[:, None]
    n = J.shape[1] - ny
    A = np.vstack([J, np.hstack([np.zeros((n, ny)), np.eye(n)])])
    return identifiability(
        J, ny, scale, _inverse(A), tuple(robot.joint_names), nuisance="the protocol's own unknowns (tool, points)"
    )


#: The masses' robot fits the arm when each joint's origin is within these of the arm's (metres,
#: radians): the same arm's URDF from another source, or the arm after an identification.
SAME_ORIGIN_M = 0.01
SAME_ORIGIN_RAD = float(np.radians(1.0))


def check_dynamics(dynamics: Robot, robot: Robot, joints: Sequence[str]) -> None:
    """Refuse masses ``dynamics`` that do not fit the arm's ``joints`` of ``robot``: a joint it has
    not (another arm's masses), a joint origin or axis more than :data:`SAME_ORIGIN_M` /
    :data:`SAME_ORIGIN_RAD` off (another arm's geometry: its moments would be in other frames), or
    no mass on the links those joints move (a URDF without ``<inertial>`` elements).

    Raises:
        InputError: one line naming what does not fit.
    """
    missing = [n for n in joints if n not in dynamics.joint_names]
    if missing:
        has = ", ".join(dynamics.joint_names) or "none"
        raise InputError(
            f"its robot has no joint {', '.join(missing)} of the arm (it has {has}): the masses must be the same arm's",
            file=dynamics.source,
        )
    for name in joints:
        A, B = robot.joint_origin(name), dynamics.joint_origin(name)
        turn = float(np.arccos(np.clip((np.trace(A[:3, :3].T @ B[:3, :3]) - 1) / 2, -1.0, 1.0)))
        axis = float(np.arccos(np.clip(robot.joint_axis(name) @ dynamics.joint_axis(name), -1.0, 1.0)))
        offset = float(np.linalg.norm(A[:3, 3] - B[:3, 3]))
        if offset > SAME_ORIGIN_M or turn > SAME_ORIGIN_RAD or axis > SAME_ORIGIN_RAD:
            raise InputError(
                f"joint {name}'s origin is {offset * 1e3:.1f} mm, {np.degrees(turn):.1f} deg and its axis "
                f"{np.degrees(axis):.1f} deg from the arm's: the masses must be the same arm's",
                file=dynamics.source,
            )
    model = dynamics.model
    ids = {model.getJointId(n) for n in joints}
    moved = sum(model.inertias[i].mass for i in range(1, model.njoints) if ids & set(model.supports[i]))
    if not moved > 0:
        raise InputError(
            "no mass on the arm's links (no <inertial> elements): compliance under gravity needs the masses",
            file=dynamics.source,
        )


def gravity_moments(dynamics: Robot, robot: Robot, Q: FloatArray) -> FloatArray:
    """``(N, robot.nq, 3)`` the moment (N·m) gravity puts through each joint of ``robot`` at
    configurations ``Q`` ``(N, robot.nq)``, in the joint's frame after its turn: its component
    along the axis is the joint's torque, the others bend the joint's bearing. From the masses of
    ``dynamics`` (a URDF of the same arm with ``<inertial>`` elements; joints matched by name,
    others zero). Joint compliance under these moments (:func:`deflection_columns`) is a
    non-geometric error a protocol may fit."""
    Q = np.atleast_2d(np.asarray(Q, dtype=float))
    names = [n for n in robot.joint_names if n in dynamics.joint_names]
    full = np.zeros((len(Q), dynamics.nq))
    full[:, [dynamics.joint_names.index(n) for n in names]] = Q[:, [robot.joint_names.index(n) for n in names]]
    model = dynamics.model
    data = model.createData()
    zero = np.zeros(model.nv)
    ids = [(robot.joint_names.index(n), model.getJointId(n)) for n in names]
    out = np.zeros((len(Q), robot.nq, 3))
    for row, q in enumerate(dynamics.to_pinocchio(full)):
        pin.rnea(model, data, q, zero, zero)
        for j, jid in ids:
            out[row, j] = data.f[jid].angular
    return out


def deflection_columns(
    robot: Robot, Q: FloatArray, points: FlangePoints, moments: FloatArray, terms: Sequence[tuple[int, int]]
) -> tuple[FloatArray, FloatArray]:
    """How a flange point moves per unit compliance of each term ``(j, a)``: joint ``j``'s frame
    turns by ``k · m_a`` (radians; ``m`` the joint's moment, ``moments`` ``(N, nq, 3)`` in the
    joint's frame after its turn, :func:`gravity_moments`) about its own axis ``a``. First order
    (deflections are ~1e-4 rad). Returns ``(G, Ω)``, each ``(N, 3, len(terms))``: the point's
    motion and the flange's world rotation per unit ``k`` (``∂(G k)/∂p = [Ω k]×``)."""
    from scipy.spatial.transform import Rotation  # lazy: start-up (scipy)

    Q = np.atleast_2d(np.asarray(Q, dtype=float))
    G = np.zeros((len(Q), 3, len(terms)))
    Omega = np.zeros((len(Q), 3, len(terms)))
    motion = point_motion(points.p)
    for m, (j, a) in enumerate(terms):
        name = robot.joint_names[j]
        if robot.joint_kinds[name] == "prismatic":
            turn = np.broadcast_to(np.eye(3), (len(Q), 3, 3))
        else:  # origin ← joint after its turn
            turn = Rotation.from_rotvec(np.outer(Q[:, j], robot.joint_axis(name))).as_matrix()
        twist = (points.W[:, j, :, 3:] @ turn[:, :, a, None])[:, :, 0] * moments[:, j, a, None]  # (N, 6)
        G[:, :, m] = np.einsum("nab,nb->na", motion, twist)
        Omega[:, :, m] = twist[:, 3:]
    return G, Omega
