"""Whole-chain calibration: one robust least-squares problem over every recorded datum.

Unknowns ``θ``: the needle tip and needle rotation on the right flange (``T_ER_Ntip``), the probe
tip frame on the left flange (``T_EL_Ptip``), the image on the probe (``T_Ptip_I``), the image's
pixel scale (per the image model), and the two reference tips (nuisance). Residuals, each
divided by its group's noise level:

- touches: ``T_R_ER @ p_ER_Mtip``, ``T_R_ER @ p_ER_Ntip`` and ``T_R_EL @ p_EL_Ptip`` against the
  reference tip they touched (3 per touch);
- axes: the tip's move p1→p2 (p1→p3) must run along the tool's y (z) axis: its component
  perpendicular to that axis (3 per move; the move's length is not recorded, so not used);
- image samples: the needle tip through the right arm against the annotated pixel through the left
  arm, ``T_R_ER p_ER_Ntip − T_R_EL T_EL_Ptip T_Ptip_I (u s_u, v s_v, 0)`` (3 per image).

Image models: ``rigid`` (the scanner's spacing), ``similarity`` (one scale), ``scaled_uv`` (a scale
per axis) and ``sound_speed`` (the physical model: lateral spacing as the scanner says, depth
spacing times c / 1540 m/s, with the speed of sound c estimated). Solved by
:func:`scipy.optimize.least_squares` (trust-region reflective, soft-L1 loss on the normalised
residuals) from the sequential result; the groups' noise levels are then re-estimated from their
residuals (robustly, by the median absolute deviation) and the problem solved again, so that
weights and covariance rest on the data. Image samples whose normalised residual exceeds 3.5 are
flagged as outliers.

Identifiability: the image samples fix only the product ``T_EL_Ptip @ T_Ptip_I`` (the probe-tip
frame is a convention); the probe touches fix ``p_EL_Ptip``, the axes moves ``R_EL_Ptip``. The
needle rotation is fixed by its axes moves alone.

Robot corrections (optional, ``joint_offsets=True``): zero offsets of the joints that this
session can tell apart from the other unknowns. :func:`identifiable_joint_offsets` measures, per
joint, how much of the residuals' response to its offset lies outside the span of the chain
parameters. Two are never identifiable here: the torso (it turns both arms together, so the
data only see it through the reference tips, which are unknown too) and each arm's last joint
(its offset is a turn about the flange axis, which the tool transforms absorb). The others are
estimated with a weak prior (0.01° SD) that keeps poorly excited ones near zero.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import approx_fprime, least_squares
from scipy.spatial.transform import Rotation

from brachycal.calibration.image_to_probe import ImageCalibration
from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.sequential import CalibrationResult
from brachycal.data.session import Session
from brachycal.errors import InputError
from brachycal.model.names import LEFT_FLANGE, RIGHT_FLANGE
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray, make_transform, transform_points

SCANNER_SOUND_SPEED = 1540.0
MODELS = ("rigid", "similarity", "scaled_uv", "sound_speed")
#: Starting noise levels (metres) of the residual groups, before they are estimated from the data.
INITIAL_SIGMA = {"touch": 1e-4, "axes": 1e-4, "image": 3e-4}
OUTLIER_THRESHOLD = 3.5


@dataclass(frozen=True)
class _Data:
    """Flange poses of every datum, computed once (the model's forward kinematics)."""

    p_ER_Mtip: FloatArray
    top: list[tuple[int, FloatArray]]  # (reference index, T_R_ER (T, 4, 4))
    needle: list[tuple[int, FloatArray]]
    probe: list[tuple[int, FloatArray]]
    needle_axes: FloatArray  # (3, 4, 4) T_R_ER at p1, p2, p3
    probe_axes: FloatArray
    T_R_ER: FloatArray  # (N, 4, 4) image samples
    T_R_EL: FloatArray
    uv_px: FloatArray
    spacing_m: FloatArray

    @classmethod
    def of(cls, session: Session, robot: Robot, offsets: FloatArray | None = None) -> _Data:
        shift = np.zeros(robot.nq) if offsets is None else offsets

        def fk(flange: str, q: FloatArray) -> FloatArray:
            return robot.fk(flange, np.atleast_2d(q) + shift)

        touches = {
            tool: [
                (k, fk(RIGHT_FLANGE if tool != "probe" else LEFT_FLANGE, session.touches[tool, ref].q))
                for k, ref in enumerate(("rtip1", "rtip2"))
            ]
            for tool in ("top_model", "needle", "probe")
        }
        return cls(
            p_ER_Mtip=session.p_ER_Mtip,
            top=touches["top_model"],
            needle=touches["needle"],
            probe=touches["probe"],
            needle_axes=fk(RIGHT_FLANGE, np.array([session.axes["needle"][p] for p in ("p1", "p2", "p3")])),
            probe_axes=fk(LEFT_FLANGE, np.array([session.axes["probe"][p] for p in ("p1", "p2", "p3")])),
            T_R_ER=fk(RIGHT_FLANGE, session.samples_q),
            T_R_EL=fk(LEFT_FLANGE, session.samples_q),
            uv_px=session.uv_px,
            spacing_m=session.spacing_m,
        )


@dataclass(frozen=True)
class _Layout:
    model: str
    offset_joints: tuple[int, ...] = ()

    @property
    def n_scale(self) -> int:
        return {"rigid": 0, "similarity": 1, "scaled_uv": 2, "sound_speed": 1}[self.model]

    @property
    def size(self) -> int:
        return 24 + self.n_scale + len(self.offset_joints)

    def offsets(self, x: FloatArray, nq: int) -> FloatArray:
        out = np.zeros(nq)
        out[list(self.offset_joints)] = x[24 + self.n_scale :]
        return out

    def unpack(self, x: FloatArray, base: dict[str, FloatArray], nominal_spacing: FloatArray):
        T_ER_Ntip = make_transform(Rotation.from_rotvec(x[3:6]).as_matrix() @ base["R_ER_Ntip"], x[0:3])
        T_EL_Ptip = make_transform(Rotation.from_rotvec(x[6:9]).as_matrix() @ base["R_EL_Ptip"], x[9:12])
        T_Ptip_I = make_transform(Rotation.from_rotvec(x[12:15]).as_matrix() @ base["R_Ptip_I"], x[15:18])
        rtips = x[18:24].reshape(2, 3)
        scale = x[24 : 24 + self.n_scale]
        if self.model == "rigid":
            spacing = nominal_spacing
        elif self.model == "similarity":
            spacing = nominal_spacing * scale[0]
        elif self.model == "scaled_uv":
            spacing = nominal_spacing * scale
        else:  # sound_speed: scale[0] is c / 1540
            spacing = nominal_spacing * [1.0, scale[0]]
        return T_ER_Ntip, T_EL_Ptip, T_Ptip_I, rtips, spacing


def finite_difference_steps(x: FloatArray) -> FloatArray:
    """Forward-difference steps for Jacobians at ``x``: 1e-7, relative for large entries."""
    return 1e-7 * np.maximum(1.0, np.abs(x))


def _perpendicular(move: FloatArray, axis: FloatArray) -> FloatArray:
    return move - (move @ axis) * axis


def _residuals(
    x: FloatArray, layout: _Layout, data: _Data, base: dict, sigma: dict[str, float], samples: np.ndarray
) -> FloatArray:
    T_ER_Ntip, T_EL_Ptip, T_Ptip_I, rtips, spacing = layout.unpack(x, base, data.spacing_m)
    parts = []
    for touches, p_tool in (
        (data.top, data.p_ER_Mtip),
        (data.needle, T_ER_Ntip[:3, 3]),
        (data.probe, T_EL_Ptip[:3, 3]),
    ):
        for k, T in touches:
            parts.append(((transform_points(T, p_tool) - rtips[k]) / sigma["touch"]).ravel())
    for T_axes, T_tool in ((data.needle_axes, T_ER_Ntip), (data.probe_axes, T_EL_Ptip)):
        tips = transform_points(T_axes, T_tool[:3, 3])
        R_tool = T_axes[0, :3, :3] @ T_tool[:3, :3]
        for point, column in ((1, 1), (2, 2)):
            parts.append(_perpendicular(tips[point] - tips[0], R_tool[:, column]) / sigma["axes"])
    parts.append(_image_residuals(data, T_ER_Ntip, T_EL_Ptip @ T_Ptip_I, spacing)[samples].ravel() / sigma["image"])
    return np.concatenate(parts)


def _image_residuals(data: _Data, T_ER_Ntip: FloatArray, T_EL_I: FloatArray, spacing: FloatArray) -> FloatArray:
    p_I = np.column_stack([data.uv_px * spacing, np.zeros(len(data.uv_px))])
    return transform_points(data.T_R_ER, T_ER_Ntip[:3, 3]) - transform_points(data.T_R_EL @ T_EL_I, p_I)


@dataclass(frozen=True)
class ChainFit:
    """One solved chain problem.

    Attributes:
        model: the image model.
        T_ER_Ntip, T_EL_Ptip: ``(4, 4)``.
        image: the image calibration (rigid ``T_Ptip_I`` and spacing).
        sound_speed_m_s: the implied speed of sound (from the depth scale; None for rigid).
        p_R_Rtip: ``(2, 3)`` reference tips.
        sigma_m: estimated noise level per residual group (touch, axes, image), metres.
        covariance: ``(P, P)`` of the parameter vector (metres, radians, scale factors).
        x: ``(P,)`` parameter vector (increments of rotations about the starting rotations).
        outliers: ``(N,)`` image samples flagged as gross errors.
        image_residuals: ``(N, 3)`` per-sample residual, metres (all samples, flagged included).
        joint_offsets_rad: estimated joint zero offsets (empty unless asked for).
    """

    model: str
    T_ER_Ntip: FloatArray
    T_EL_Ptip: FloatArray
    image: ImageCalibration
    sound_speed_m_s: float | None
    p_R_Rtip: FloatArray
    sigma_m: dict[str, float]
    covariance: FloatArray
    x: FloatArray
    base: dict[str, FloatArray] = field(repr=False)
    outliers: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    image_residuals: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    joint_offsets_rad: dict[str, float] = field(default_factory=dict)

    def offsets(self, joint_names: tuple[str, ...]) -> FloatArray:
        """``(nq,)`` estimated joint zero offsets (zeros unless estimated), radians."""
        return np.array([self.joint_offsets_rad.get(name, 0.0) for name in joint_names])

    def parameter_sd(self) -> FloatArray:
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))


def _start(initial: CalibrationResult, layout: _Layout, nominal_spacing: FloatArray) -> tuple[FloatArray, dict]:
    image = initial.image.get("scaled_uv") or next(iter(initial.image.values()))
    base = {
        "R_ER_Ntip": initial.T_ER_Ntip[:3, :3],
        "R_EL_Ptip": initial.T_EL_Ptip[:3, :3],
        "R_Ptip_I": image.T_Ptip_I[:3, :3],
    }
    x = np.zeros(layout.size)
    x[0:3] = initial.T_ER_Ntip[:3, 3]
    x[9:12] = initial.T_EL_Ptip[:3, 3]
    x[15:18] = image.T_Ptip_I[:3, 3]
    x[18:21], x[21:24] = initial.p_R_Rtip["rtip1"], initial.p_R_Rtip["rtip2"]
    ratio = image.spacing_m / nominal_spacing
    if layout.model == "similarity":
        x[24] = ratio.mean()
    elif layout.model == "scaled_uv":
        x[24:26] = ratio
    elif layout.model == "sound_speed":
        x[24] = ratio[1]
    return x, base


#: Prior SD of an estimated joint zero offset (rad): keeps weakly excited offsets near zero.
OFFSET_PRIOR_SD = np.radians(0.01)


def fit_chain(
    session: Session,
    robot: Robot,
    initial: CalibrationResult,
    model: str = "scaled_uv",
    *,
    samples: np.ndarray | None = None,
    rounds: int = 2,
    joint_offsets: bool = False,
) -> ChainFit:
    """Solve the whole chain with one image model.

    Args:
        session: the recorded data.
        robot: the model giving flange poses.
        initial: the sequential result (starting values).
        model: one of :data:`MODELS`.
        samples: ``(N,)`` bool mask of image samples to use (for cross-validation; default all).
        rounds: solves, each re-estimating the groups' noise levels from the previous residuals.
        joint_offsets: also estimate the zero offsets of the joints this session identifies.
    """
    if model not in MODELS:
        raise InputError(f"unknown image model {model!r}; choose from {', '.join(MODELS)}")
    data = _Data.of(session, robot)
    joints: tuple[int, ...] = ()
    if joint_offsets:
        first = fit_chain(session, robot, initial, model, samples=samples, rounds=rounds)
        ratios = identifiable_joint_offsets(session, robot, first)
        joints = tuple(k for k, name in enumerate(robot.joint_names) if ratios[name] > 0.05)
    layout = _Layout(model, joints)
    x, base = _start(initial, layout, data.spacing_m)
    use = np.ones(len(data.uv_px), dtype=bool) if samples is None else np.asarray(samples, dtype=bool)
    sigma = dict(INITIAL_SIGMA)

    def data_at(x: FloatArray) -> _Data:
        return _Data.of(session, robot, layout.offsets(x, robot.nq)) if joints else data

    def residual(x: FloatArray) -> FloatArray:
        r = _residuals(x, layout, data_at(x), base, sigma, use)
        return np.concatenate([r, x[24 + layout.n_scale :] / OFFSET_PRIOR_SD]) if joints else r

    def solve(x: FloatArray):
        return least_squares(
            residual,
            x,
            method="trf",
            loss="soft_l1",
            f_scale=1.0,
            x_scale="jac",
            xtol=1e-15,
            ftol=1e-15,
            gtol=1e-15,
            max_nfev=200,
        )

    for _ in range(rounds):
        x = solve(x).x
        sigma = _group_sigmas(x, layout, data_at(x), base, sigma, use)
    fit = solve(x)
    x = fit.x
    covariance = np.linalg.pinv(fit.jac.T @ fit.jac, rcond=1e-12)
    T_ER_Ntip, T_EL_Ptip, T_Ptip_I, rtips, spacing = layout.unpack(x, base, data.spacing_m)
    residuals = _image_residuals(data_at(x), T_ER_Ntip, T_EL_Ptip @ T_Ptip_I, spacing)
    outliers = np.linalg.norm(residuals, axis=1) / (np.sqrt(3.0) * sigma["image"]) > OUTLIER_THRESHOLD
    sound = None if model in ("rigid",) else float(SCANNER_SOUND_SPEED * spacing[1] / data.spacing_m[1])
    offsets = {robot.joint_names[k]: float(v) for k, v in zip(joints, x[24 + layout.n_scale :], strict=True)}
    return ChainFit(
        model,
        T_ER_Ntip,
        T_EL_Ptip,
        ImageCalibration("chain", T_Ptip_I, spacing),
        sound,
        rtips,
        sigma,
        covariance,
        x,
        base,
        outliers,
        residuals,
        offsets,
    )


def _group_sigmas(
    x: FloatArray, layout: _Layout, data: _Data, base: dict, sigma: dict[str, float], use: np.ndarray
) -> dict[str, float]:
    """Noise level per group from its residuals: 1.4826 × the median absolute residual per coordinate."""
    ones = {k: 1.0 for k in sigma}
    r = _residuals(x, layout, data, base, ones, use)
    n_touch = 3 * sum(len(T) for touches in (data.top, data.needle, data.probe) for _, T in touches)
    groups = {"touch": r[:n_touch], "axes": r[n_touch : n_touch + 12], "image": r[n_touch + 12 :]}
    floor = {"touch": 1e-6, "axes": 1e-6, "image": 1e-6}
    return {k: max(1.4826 * float(np.median(np.abs(v))), floor[k]) for k, v in groups.items()}


def cross_validate(
    session: Session,
    robot: Robot,
    initial: CalibrationResult,
    model: str,
    folds: int = 8,
    seed: int = 0,
    exclude: np.ndarray | None = None,
) -> ErrorStats:
    """K-fold cross-validated image error of a chain model: each fold's samples predicted by a fit
    without them. Samples in ``exclude`` (flagged outliers) are fitted robustly but not scored."""
    n = len(session.uv_px)
    order = np.random.default_rng(seed).permutation(n)
    errors = np.empty(n)
    data = _Data.of(session, robot)
    for fold in range(folds):
        held = np.zeros(n, dtype=bool)
        held[order[fold::folds]] = True
        fit = fit_chain(session, robot, initial, model, samples=~held, rounds=1)
        residuals = _image_residuals(data, fit.T_ER_Ntip, fit.T_EL_Ptip @ fit.image.T_Ptip_I, fit.image.spacing_m)
        errors[held] = np.linalg.norm(residuals[held], axis=1)
    keep = np.ones(n, dtype=bool) if exclude is None else ~np.asarray(exclude, dtype=bool)
    return ErrorStats(errors[keep])


@dataclass(frozen=True)
class ModelChoice:
    """The chosen image model and the evidence: cross-validated errors per model (outliers not scored)."""

    model: str
    cv: dict[str, ErrorStats]
    rule: str
    scored_samples: int

    def evidence(self) -> dict[str, dict[str, float]]:
        out = {}
        for m, s in self.cv.items():
            squares = (s.errors_m * 1e3) ** 2
            se_rmse = float(np.std(squares) / np.sqrt(s.n) / (2 * s.rmse_mm))  # delta method on mean(e²)
            out[m] = {"cv_rmse_mm": s.rmse_mm, "cv_mae_mm": s.mae_mm, "se_mm": se_rmse}
        return out


COMPLEXITY = {"rigid": 0, "similarity": 1, "sound_speed": 1, "scaled_uv": 2}


def select_model(
    session: Session, robot: Robot, initial: CalibrationResult, models: tuple[str, ...] = MODELS, folds: int = 8
) -> ModelChoice:
    """Choose the image model by K-fold CV: the simplest model within one standard error of the best.

    Samples that the most flexible model flags as gross outliers are left out of the scores (they
    would dominate every model's error alike).
    """
    flagged = fit_chain(session, robot, initial, "scaled_uv").outliers
    cv = {m: cross_validate(session, robot, initial, m, folds, exclude=flagged) for m in models}
    rule = "simplest model within one standard error of the lowest cross-validated RMSE (outliers not scored)"
    evidence = ModelChoice("", cv, rule, int((~flagged).sum())).evidence()
    best = min(evidence, key=lambda m: evidence[m]["cv_rmse_mm"])
    limit = evidence[best]["cv_rmse_mm"] + evidence[best]["se_mm"]
    eligible = [m for m in models if evidence[m]["cv_rmse_mm"] <= limit]
    chosen = min(eligible, key=lambda m: (COMPLEXITY[m], evidence[m]["cv_rmse_mm"]))
    return ModelChoice(chosen, cv, rule, int((~flagged).sum()))


def identifiable_joint_offsets(
    session: Session, robot: Robot, fit: ChainFit, tolerance: float = 0.05
) -> dict[str, float]:
    """How much of each joint's zero-offset effect the chain parameters cannot absorb.

    For joint k, the residuals' derivative with respect to a common offset of that joint in every
    recorded configuration is compared with the span of the chain parameters' Jacobian; the
    returned number is the part left outside that span (0: fully confounded, 1: independent).
    A joint offset is identifiable from this session when that part exceeds ``tolerance``.
    """
    layout = _Layout(fit.model)
    use = np.ones(len(session.uv_px), dtype=bool)
    data = _Data.of(session, robot)
    sigma = fit.sigma_m

    def residuals(data_k: _Data) -> FloatArray:
        return _residuals(fit.x, layout, data_k, fit.base, sigma, use)

    r0 = residuals(data)
    J = approx_fprime(fit.x, _residuals, finite_difference_steps(fit.x), layout, data, fit.base, sigma, use)
    Q, _ = np.linalg.qr(J)
    out = {}
    step = 1e-6
    for k, name in enumerate(robot.joint_names):
        shifted = _shift_joint(session, k, step)
        column = (residuals(_Data.of(shifted, robot)) - r0) / step
        norm_column = np.linalg.norm(column)
        out[name] = 0.0 if norm_column == 0 else float(np.linalg.norm(column - Q @ (Q.T @ column)) / norm_column)
    return out


def _shift_joint(session: Session, k: int, delta: float) -> Session:
    from dataclasses import replace

    def shift(q: FloatArray) -> FloatArray:
        q = np.array(q, dtype=float, copy=True)
        q[..., k] += delta
        return q

    touches = {key: replace(t, q=shift(t.q)) for key, t in session.touches.items()}
    axes = {tool: {p: shift(q) for p, q in points.items()} for tool, points in session.axes.items()}
    return replace(session, touches=touches, axes=axes, samples_q=shift(session.samples_q))


def information_blocks(session: Session, robot: Robot, fit: ChainFit) -> tuple[FloatArray, FloatArray]:
    """Fisher information of the fit's parameters, split by source (no joint offsets).

    Returns ``(I_fixed (P, P), J_samples (N, 3, P))``: the information from the touches and axes
    moves, and each image sample's Jacobian block (normalised by the noise levels), so that a
    design's information is ``I_fixed + Σ_selected J_iᵀ J_i``.
    """
    layout = _Layout(fit.model)
    data = _Data.of(session, robot)
    use = np.ones(len(session.uv_px), dtype=bool)
    x = fit.x[: layout.size]
    J = approx_fprime(x, _residuals, finite_difference_steps(x), layout, data, fit.base, fit.sigma_m, use)
    n_images = 3 * len(session.uv_px)
    fixed = J[:-n_images]
    return fixed.T @ fixed, J[-n_images:].reshape(len(session.uv_px), 3, layout.size)
