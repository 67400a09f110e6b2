"""Which extra observations would identify the robot best: an A-optimal criterion on the landing error.

Design: ``docs/design/robot_identification.md``, "Which observations identify the robot best".
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from brachycal.calibration.chain import ChainData, chain_jacobian, robot_jacobian_at
from brachycal.calibration.chain.uncertainty import landing_jacobian, landing_robot_jacobians
from brachycal.calibration.robot.identification import IdentificationResult, prior_sd
from brachycal.data.session import Session, Touches
from brachycal.errors import InputError
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray

#: Kinds of extra observation.
TOUCH, SAMPLE = "touch", "sample"


@dataclass(frozen=True)
class Observation:
    """One extra observation: a touch of reference tip ``reference`` by ``tool`` (``needle``,
    ``probe`` or ``top_model``) at joints ``q (nq,)``, or an image sample at ``q`` with the needle tip
    at pixel ``uv_px (2,)``."""

    kind: str
    q: FloatArray
    tool: str = ""
    reference: str = ""
    uv_px: FloatArray = field(default_factory=lambda: np.zeros(2))

    def __post_init__(self) -> None:
        if self.kind not in (TOUCH, SAMPLE):
            raise InputError(f"observation kind must be {TOUCH!r} or {SAMPLE!r}, got {self.kind!r}")
        if self.kind == TOUCH and (self.tool, self.reference) == ("", ""):
            raise InputError("a touch names its tool and reference tip")


def extended_session(session: Session, extra: Sequence[Observation], prefix: str = "x") -> Session:
    """``session`` with the observations appended: touches as further trials of their tool and
    reference tip (numbered on from the last), samples after the session's (named ``prefix001``…).

    ``extra`` must carry the joints as read and the pixels as annotated (in-memory; a session file
    pairs the tools' trials one to one, so extra touches are not written back as a session)."""
    touches = dict(session.touches)
    for obs in (o for o in extra if o.kind == TOUCH):
        key = (obs.tool, obs.reference)
        if key not in touches:
            raise InputError(f"no touches of {obs.tool} at {obs.reference} in the session to extend")
        old = touches[key]
        touches[key] = Touches(np.append(old.trials, old.trials.max() + 1), np.vstack([old.q, obs.q]))
    samples = [o for o in extra if o.kind == SAMPLE]
    # A session built in memory: no input files hashed (``inputs`` empty).
    if not samples:
        return replace(session, touches=touches, inputs={})
    return replace(
        session,
        touches=touches,
        sample_ids=[*session.sample_ids, *(f"{prefix}{k + 1:03d}" for k in range(len(samples)))],
        samples_q=np.vstack([session.samples_q, [o.q for o in samples]]),
        uv_px=np.vstack([session.uv_px, [o.uv_px for o in samples]]),
        inputs={},
    )


def observation_rows(
    identified: IdentificationResult, session: Session, nominal: Robot, extra: Sequence[Observation]
) -> list[FloatArray]:
    """Each observation's normalised rows ``(3, n)`` over ``δ = (θ, c/s)`` (module docstring), at the
    identification's estimate, with its noise levels (``touch`` or ``image``)."""
    fit = identified.fit
    corrected = identified.robot(nominal)
    layout = fit.layout(nominal.joint_names)
    extended = extended_session(session, extra)
    n_samples = len(extended.uv_px)
    keep = np.ones(n_samples, dtype=bool)
    data = ChainData.of(extended, corrected)
    J_x = chain_jacobian(fit.x, layout, data, fit.base, fit.sigma_m, keep)
    J_c = robot_jacobian_at(extended, corrected, layout, fit.x, fit.base, fit.sigma_m, keep)
    J = np.hstack([J_x, J_c * prior_sd(nominal, identified.accuracy)])
    # Where each appended touch's rows are: tools, then references, then trials (ChainData's order).
    start, where = 0, {}
    for tool in ("top_model", "needle", "probe"):
        for reference in ("rtip1", "rtip2"):
            count = len(extended.touches[tool, reference].trials)
            where[tool, reference] = (start, count, len(session.touches[tool, reference].trials))
            start += 3 * count
    image = data.group_rows(n_samples)["image"].start
    rows, used = [], dict.fromkeys(where, 0)
    k_sample = len(session.uv_px)
    for obs in extra:
        if obs.kind == TOUCH:
            first, _, old = where[obs.tool, obs.reference]
            r = first + 3 * (old + used[obs.tool, obs.reference])
            used[obs.tool, obs.reference] += 1
        else:
            r = image + 3 * k_sample
            k_sample += 1
        rows.append(J[r : r + 3])
    return rows


def landing_weights(
    identified: IdentificationResult, nominal: Robot, spacing_m: FloatArray, q: FloatArray, uv_px: FloatArray
) -> tuple[FloatArray, float]:
    """``H (n, n) = mean_t W_tᵀ W_t`` over targeting poses ``q (M, nq)``, ``uv_px (M, 2)``, and the
    encoder noise's constant mean squared landing error (m²) there (module docstring)."""
    fit = identified.fit
    corrected = identified.robot(nominal)
    G = landing_jacobian(fit, corrected, spacing_m, q, uv_px)
    L_c, L_q = landing_robot_jacobians(fit, corrected, spacing_m, q, uv_px)
    W = np.concatenate([G, -L_c * prior_sd(nominal, identified.accuracy)], axis=2)
    H = np.einsum("tip,tiq->pq", W, W) / len(W)
    constant = identified.accuracy.encoder_sd_rad**2 * float(np.mean(np.sum(L_q**2, axis=(1, 2))))
    return H, constant


@dataclass
class Criterion:
    """The predicted mean squared landing error ``trace(H Σ) + constant`` (m²) and its updates.

    Attributes:
        posterior: ``(n, n)`` the current ``Σ`` (prior units for the robot part), updated by :meth:`add`.
        H: ``(n, n)`` the landing weights.
        constant_m2: what no observation changes (the encoder noise when aiming).
    """

    posterior: FloatArray
    H: FloatArray
    constant_m2: float = 0.0

    @property
    def mse_m2(self) -> float:
        return float(np.trace(self.H @ self.posterior)) + self.constant_m2

    @property
    def rms_mm(self) -> float:
        return float(np.sqrt(self.mse_m2) * 1e3)

    def gains(self, blocks: Sequence[FloatArray]) -> FloatArray:
        """``(m,)`` how much each block of rows ``(k, n)`` alone would lower the mean squared error, m²."""
        out = np.empty(len(blocks))
        for k, B in enumerate(blocks):
            BS = B @ self.posterior
            M = np.eye(len(B)) + BS @ B.T
            out[k] = np.trace(np.linalg.solve(M, BS @ self.H @ BS.T))
        return out

    def add(self, B: FloatArray) -> None:
        """Take the rows ``B (k, n)`` into the posterior (Woodbury)."""
        BS = B @ self.posterior
        M = np.eye(len(B)) + BS @ B.T
        self.posterior = self.posterior - BS.T @ np.linalg.solve(M, BS)
        self.posterior = 0.5 * (self.posterior + self.posterior.T)


def session_rows(identified: IdentificationResult, session: Session, nominal: Robot) -> dict[str, FloatArray]:
    """The session's own normalised rows over ``δ = (θ, c/s)`` at the estimate, per residual group
    (``touch``, ``axes``, ``image``; the samples the fit used): ``AᵀA`` is their sum plus the prior's."""
    fit = identified.fit
    corrected = identified.robot(nominal)
    layout = fit.layout(nominal.joint_names)
    keep = ~fit.outliers
    data = ChainData.of(session, corrected)
    J_x = chain_jacobian(fit.x, layout, data, fit.base, fit.sigma_m, keep)
    J_c = robot_jacobian_at(session, corrected, layout, fit.x, fit.base, fit.sigma_m, keep)
    J = np.hstack([J_x, J_c * prior_sd(nominal, identified.accuracy)])
    return {g: J[rows] for g, rows in data.group_rows(int(keep.sum())).items()}


def resolution(identified: IdentificationResult, session: Session, nominal: Robot, criterion: Criterion) -> float:
    """Relative SD of the predicted RMS landing error from the noise levels' own uncertainty.

    Each group's variance ``σ_g²`` was estimated from ``ν_g`` residual degrees of freedom, so
    ``log σ_g²`` has an SD of about ``√(2/ν_g)``; the predicted mean squared error moves with it by
    ``∂ MSE / ∂ log σ_g² = trace(H Σ N_g Σ)`` (``N_g`` the group's information: scaling its variance
    scales its information inversely). The relative SD of the RMS is half that of the MSE:
    ``½ √(Σ_g (share_g)² 2/ν_g)``, ``share_g = trace(H Σ N_g Σ) / MSE``. Groups whose level was
    assumed rather than estimated contribute nothing here.
    """
    rows = session_rows(identified, session, nominal)
    S, H = criterion.posterior, criterion.H
    variance = 0.0
    for group, level in identified.fit.noise.items():
        if group not in rows or level.source != "residuals" or level.dof <= 0:
            continue
        J = rows[group]
        share = float(np.trace(H @ S @ J.T @ J @ S)) / criterion.mse_m2
        variance += share**2 * 2.0 / level.dof
    return float(0.5 * np.sqrt(variance))


@dataclass(frozen=True)
class Selection:
    """What :func:`greedy` chose: candidate indices in order, the predicted RMS landing error before
    and after each (mm), the minutes each costs and the resolution it was judged with."""

    chosen: list[int]
    rms_before_mm: float
    rms_after_mm: list[float]
    minutes: list[float]
    resolution: float
    worth_it: bool

    @property
    def rms_mm(self) -> float:
        return self.rms_after_mm[-1] if self.rms_after_mm else self.rms_before_mm

    @property
    def total_minutes(self) -> float:
        return float(sum(self.minutes))


def greedy(
    criterion: Criterion,
    blocks: Sequence[FloatArray],
    minutes: Sequence[float],
    budget_minutes: float,
    resolution_fraction: float,
) -> Selection:
    """Greedy A-optimal choice under a budget: at each step the candidate with the largest gain per
    minute among those that still fit; stops when none fits or the best lowers the predicted RMS by
    less than ``resolution_fraction / budget_minutes`` of it per minute (module docstring).
    ``criterion`` is updated with the chosen rows."""
    cost = np.asarray(minutes, dtype=float)
    if len(cost) != len(blocks) or np.any(~np.isfinite(cost)) or np.any(cost <= 0):
        raise InputError("every candidate needs a positive, finite cost in minutes")
    before = criterion.rms_mm
    chosen: list[int] = []
    after: list[float] = []
    spent: list[float] = []
    available = np.ones(len(blocks), dtype=bool)
    rate_floor = resolution_fraction / budget_minutes
    while True:
        available &= cost <= budget_minutes - sum(spent) + 1e-12
        if not available.any():
            break
        index = np.flatnonzero(available)
        mse = criterion.mse_m2
        gains = criterion.gains([blocks[int(i)] for i in index])
        # Relative fall of the RMS per minute, candidate by candidate.
        rate = (1.0 - np.sqrt(np.clip(mse - gains, 0.0, None) / mse)) / cost[index]
        best = int(np.argmax(rate))
        if not rate[best] >= rate_floor:
            break
        i = int(index[best])
        criterion.add(blocks[i])
        chosen.append(i)
        after.append(criterion.rms_mm)
        spent.append(float(cost[i]))
        available[i] = False
    worth = bool(chosen) and 1.0 - (after[-1] / before) >= resolution_fraction
    return Selection(chosen, before, after, spent, resolution_fraction, worth)


def base_criterion(
    identified: IdentificationResult,
    session: Session,
    nominal: Robot,
    targets: tuple[FloatArray, FloatArray] | None = None,
) -> Criterion:
    """The criterion of ``identified`` (on ``session``, calibrated with ``nominal``) at the targeting
    poses ``targets = (q (M, nq), uv_px (M, 2))`` (default: the session's samples the fit used)."""
    if targets is None:
        keep = ~identified.fit.outliers
        targets = (session.samples_q[keep], session.uv_px[keep])
    H, constant = landing_weights(identified, nominal, session.spacing_m, *targets)
    return Criterion(identified.posterior.copy(), H, constant)
