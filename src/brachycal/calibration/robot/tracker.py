"""Robot identification from an external tracker: any arm, a marker on it seen in 3-D or 6-D.

Each posture ``n`` has joint values ``q_n`` and the tracker's measurement of a marker rigidly on a
flange: its position ``p_tracker_marker`` (and, 6-D, its orientation ``R_tracker_marker``). Neither
the tracker's frame nor the marker's place on the flange is known. The model::

    T_tracker_marker(n) = T_tracker_base · T_base_flange(q_n; c) · T_flange_marker

with unknowns

- ``T_tracker_base`` (6), updated on the right: ``T ← T · exp(ξ)``, ``ξ`` in the base frame;
- the marker: its position on the flange ``p_flange_marker`` (3) or, 6-D, its pose (6, updated on
  the left in the flange frame: ``T ← exp(ξ) · T``);
- the robot's geometry ``c`` (:func:`~brachycal.calibration.robot.identification.corrected_robot`'s
  joint-origin corrections ``(v, ω)`` per joint), in one of three models (:data:`TRACKER_MODELS`):
  ``frames`` (none: the URDF as it is), ``offsets`` (each joint's zero: ``ω`` along a revolute
  joint's axis, ``v`` along a prismatic one's), ``joints`` (every component). Only the components
  the data can see at all are estimated: the columns of the corrections' Jacobian, projected off
  the frames' span (the frames are free), are ranked by a pivoted QR and those past the numerical
  rank dropped (the structural base set, as FIGAROH's QR reduction finds it: e.g. the first joint's
  zero is the tracker frame's rotation, the last joint's origin the marker's place).

The estimate is the maximum a posteriori one: residuals over their noise levels (one per kind,
position and orientation, estimated from the residuals with leverage-corrected degrees of freedom,
re-estimated over :data:`NOISE_ROUNDS` rounds) and the kept corrections over their prior SD (the
stated accuracy, :class:`~brachycal.calibration.robot_accuracy.RobotAccuracy`); the frames have no
prior. Gauss–Newton, the robot's Jacobian analytic through
:func:`~brachycal.calibration.chain.robot_terms.joint_twists`.

The headline figure is leave-one-out over postures (each posture predicted by a fit made without
it), training second: with tens of postures and tens of parameters a training figure flatters.
*Fit only what the data support*: a richer model replaces the chosen one only if its leave-one-out
mean squared position error is lower by more than the standard error of the paired differences
over the held-out postures; otherwise the smaller model is returned and the report says so.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from brachycal.calibration.chain.robot_terms import joint_twists
from brachycal.calibration.robot.identifiability import COMPONENTS, STRUCTURAL_RCOND
from brachycal.calibration.robot.identification import corrected_robot, prior_sd
from brachycal.calibration.robot_accuracy import RobotAccuracy
from brachycal.calibration.sequential.registration import kabsch
from brachycal.data.formats.tracker_table import TrackerTable
from brachycal.errors import DegenerateDataError, InputError
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray, left_jacobian, make_transform, rotation, skew

__all__ = [
    "TRACKER_ACCURACY",
    "TRACKER_MODELS",
    "ModelScore",
    "TrackerData",
    "TrackerFit",
    "TrackerIdentification",
    "fit_tracker",
    "identify_from_tracker",
    "leave_one_out",
    "tracker_data",
]

#: The models, from the smallest: the URDF as it is, joint zeros, every joint-origin component.
TRACKER_MODELS = ("frames", "offsets", "joints")
#: Default prior of the corrections: an industrial arm off its URDF by ~1 mm / 0.1° per joint
#: origin (real arms measured by trackers are; the twin's default 0.03 mm / 0.003° is a
#: well-built arm's and would hold real errors in the frames).
TRACKER_ACCURACY = RobotAccuracy(
    translation_sd_m=1e-3,
    rotation_sd_rad=float(np.radians(0.1)),
    source="tracker default: an industrial arm, 1 mm / 0.1 deg per joint origin",
)
#: Noise-level rounds of one fit (the levels settle to 1e-3 relative in 3 on the FIGAROH data).
NOISE_ROUNDS = 3
#: Gauss–Newton iterations per round, and the stop: the largest step below this (metres, radians).
ITERATIONS = 30
STEP_TOLERANCE = 1e-12
#: Also stop when a step lowers the cost by less than this fraction (its last digits).
COST_TOLERANCE = 1e-14
#: Step halvings tried before a Gauss–Newton step is given up (the minimum reached to rounding).
HALVINGS = 8
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


# --- the model's parameters ------------------------------------------------------------------


def candidate_columns(robot: Robot, model: str, flange: str) -> tuple[FloatArray, list[str]]:
    """``(6 nq, K)`` unit directions of the corrections a model may estimate, and their names
    (``joint.vx`` … ``joint.wz``, ``joint.offset``): only joints that move the flange."""
    if model not in TRACKER_MODELS:
        raise InputError(f"unknown model {model!r}; expected one of {', '.join(TRACKER_MODELS)}")
    W = joint_twists(robot, robot.neutral()[None], flange)[0]
    columns: list[FloatArray] = []
    names: list[str] = []
    for j, name in enumerate(robot.joint_names):
        if model == "frames" or not np.any(W[j]):
            continue
        if model == "offsets":
            axis = robot.joint_axis(name)
            e = np.zeros(6 * robot.nq)
            e[6 * j + (0 if robot.in_metres[j] else 3) : 6 * j + (3 if robot.in_metres[j] else 6)] = axis
            columns.append(e)
            names.append(f"{name}.offset")
        else:
            for k in range(6):
                e = np.zeros(6 * robot.nq)
                e[6 * j + k] = 1.0
                columns.append(e)
                names.append(f"{name}.{COMPONENTS[k]}")
    B = np.array(columns).T if columns else np.zeros((6 * robot.nq, 0))
    return B, names


@dataclass
class _State:
    """The unknowns' current values."""

    T_tracker_base: FloatArray
    T_flange_marker: FloatArray
    theta: FloatArray  # (K,) the kept corrections' values (metres / radians)


class _Kinematics:
    """The flange's pose and the joint origins' twists (:func:`joint_twists`' convention) of the
    robot with corrections, from a private copy of its Pinocchio model whose joint placements are
    set in place (``placement · T(exp(ω), v)``, what :func:`corrected_robot` writes into the
    URDF): the fits evaluate thousands of corrected robots, and rebuilding each from its URDF
    costs ~50 ms where this costs ~1 ms."""

    def __init__(self, robot: Robot, flange: str) -> None:
        import pinocchio as pin  # lazy: start-up (pinocchio)

        self.pin = pin
        self.robot = robot
        self.model = pin.Model(robot.model)
        self.data = self.model.createData()
        self.frame = robot.frame_id(flange)
        support = set(self.model.supports[self.model.frames[self.frame].parentJoint])
        ids = [self.model.getJointId(n) for n in robot.joint_names]
        self.moving = [(j, jid) for j, jid in enumerate(ids) if jid in support]
        self.placements = {jid: self.model.jointPlacements[jid].copy() for _, jid in self.moving}

    def evaluate(self, Q: FloatArray, c: FloatArray, twists: bool) -> tuple[FloatArray, FloatArray | None]:
        """``(T_base_flange (N, 4, 4), W (N, nq, 6, 6) or None)`` at ``Q (N, nq)``, corrections ``c (nq, 6)``."""
        pin, model, data = self.pin, self.model, self.data
        for j, jid in self.moving:
            model.jointPlacements[jid] = self.placements[jid] * pin.SE3(rotation(c[j, 3:]), c[j, :3])
        Q_pin = self.robot.to_pinocchio(Q)
        T = np.empty((len(Q), 4, 4))
        W = np.zeros((len(Q), self.robot.nq, 6, 6)) if twists else None
        for n, q in enumerate(Q_pin):
            pin.forwardKinematics(model, data, q)
            T[n] = pin.updateFramePlacement(model, data, self.frame).homogeneous
            if W is not None:
                for j, jid in self.moving:
                    origin = data.oMi[model.parents[jid]] * model.jointPlacements[jid]
                    R, t = origin.rotation, origin.translation
                    W[n, j, :3, :3] = R
                    W[n, j, :3, 3:] = skew(t) @ R
                    W[n, j, 3:, 3:] = R
        return T, W


@dataclass(frozen=True)
class _Problem:
    """One model on one data set: the residuals, their Jacobian, the prior."""

    data: TrackerData
    B: FloatArray  # (6 nq, K) kept correction directions
    prior: FloatArray  # (K,) their prior SD
    kinematics: _Kinematics

    @property
    def marker_size(self) -> int:
        return 6 if self.data.six_d else 3

    @property
    def frame_size(self) -> int:
        return 6 + self.marker_size

    def corrections(self, theta: FloatArray) -> FloatArray:
        return (self.B @ theta).reshape(self.data.robot.nq, 6)

    def predict(self, s: _State, twists: bool = False) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray | None]:
        """``(T_base_flange (N,4,4), p (N,3), R (N,3,3), W or None)`` at the data's postures."""
        T_bf, W = self.kinematics.evaluate(self.data.Q, self.corrections(s.theta), twists)
        T = s.T_tracker_base @ T_bf @ s.T_flange_marker
        return T_bf, T[:, :3, 3], T[:, :3, :3], W

    def residuals(self, s: _State) -> tuple[FloatArray, FloatArray | None]:
        """``(N, 3)`` position residuals (predicted − measured, metres) and, 6-D, ``(N, 3)``
        orientation residuals ``log(R_pred R_measᵀ)`` (radians, tracker frame)."""
        _, p, R, _ = self.predict(s)
        r_p = p - self.data.p
        if self.data.R is None:
            return r_p, None
        return r_p, _log(R @ np.swapaxes(self.data.R, 1, 2))

    def jacobian(self, s: _State) -> tuple[FloatArray, FloatArray | None]:
        """``(N, 3, P)`` of the position residuals and, 6-D, ``(N, 3, P)`` of the orientation
        residuals, with respect to ``(ξ_base, marker, θ)`` (module docstring's updates)."""
        d = self.data
        T_bf, _, R_pred, W = self.predict(s, twists=bool(self.B.shape[1]))
        N, K, m = len(d.Q), self.B.shape[1], self.marker_size
        R_tb = s.T_tracker_base[:3, :3]
        p_fm = s.T_flange_marker[:3, 3]
        x_b = T_bf[:, :3, :3] @ p_fm + T_bf[:, :3, 3]  # the marker in the base frame
        motion = np.concatenate([np.broadcast_to(np.eye(3), (N, 3, 3)), -skew(x_b)], axis=2)  # (N, 3, 6)
        Jp = np.zeros((N, 3, self.frame_size + K))
        Jp[:, :, :6] = R_tb @ motion
        R_tf = R_tb @ T_bf[:, :3, :3]
        Jp[:, :, 6:9] = R_tf
        if m == 6:
            Jp[:, :, 9:12] = -R_tf @ skew(p_fm)
        if W is not None:
            Wc = np.einsum("njab,jbk->nak", W, self.B.reshape(d.robot.nq, 6, K))  # (N, 6, K)
            Jp[:, :, self.frame_size :] = R_tb @ motion @ Wc
        if d.R is None:
            return Jp, None
        Jo = np.zeros_like(Jp)
        Jo[:, :, 3:6] = np.broadcast_to(R_tb, (N, 3, 3))
        Jo[:, :, 9:12] = R_tf
        if W is not None:
            Jo[:, :, self.frame_size :] = R_tb @ Wc[:, 3:]
        r_o = _log(R_pred @ np.swapaxes(d.R, 1, 2))
        J_inv = np.array([np.linalg.inv(left_jacobian(r)) for r in r_o])
        return Jp, J_inv @ Jo

    def update(self, s: _State, step: FloatArray) -> _State:
        m = self.marker_size
        T_tb = s.T_tracker_base @ _exp(step[:6])
        if m == 6:
            T_fm = _exp(step[6:12]) @ s.T_flange_marker
        else:
            T_fm = s.T_flange_marker.copy()
            T_fm[:3, 3] += step[6:9]
        return _State(T_tb, T_fm, s.theta + step[self.frame_size :])

    def normalised(self, s: _State, sigma: dict[str, float]) -> tuple[FloatArray, FloatArray, list[str]]:
        """Stacked residuals and Jacobian over their noise levels, and each row's kind."""
        r_p, r_o = self.residuals(s)
        Jp, Jo = self.jacobian(s)
        r = [r_p.ravel() / sigma["position"]]
        J = [Jp.reshape(-1, Jp.shape[2]) / sigma["position"]]
        kinds = ["position"] * r_p.size
        if r_o is not None and Jo is not None:
            r.append(r_o.ravel() / sigma["orientation"])
            J.append(Jo.reshape(-1, Jo.shape[2]) / sigma["orientation"])
            kinds += ["orientation"] * r_o.size
        return np.concatenate(r), np.vstack(J), kinds

    def augmented(self, s: _State, sigma: dict[str, float]) -> tuple[FloatArray, FloatArray, list[str]]:
        """:meth:`normalised` with the prior's rows ``θ / prior`` appended."""
        r, J, kinds = self.normalised(s, sigma)
        K = len(self.prior)
        if K:
            rows = np.zeros((K, J.shape[1]))
            rows[:, self.frame_size :] = np.diag(1.0 / self.prior)
            r, J = np.concatenate([r, s.theta / self.prior]), np.vstack([J, rows])
        return r, J, kinds

    def solve(self, s: _State, sigma: dict[str, float]) -> _State:
        """Gauss–Newton on the augmented problem, halving a step that raises the cost."""
        r, J, _ = self.augmented(s, sigma)
        cost = float(r @ r)
        for _ in range(ITERATIONS):
            step = np.linalg.lstsq(J, -r, rcond=None)[0]
            for _ in range(HALVINGS):
                trial = self.update(s, step)
                r_t, J_t, _ = self.augmented(trial, sigma)
                if float(r_t @ r_t) <= cost:
                    break
                step = step / 2
            else:
                break  # no step lowers the cost: at the minimum to rounding
            gain = cost - float(r_t @ r_t)
            s, r, J, cost = trial, r_t, J_t, float(r_t @ r_t)
            if np.max(np.abs(step)) < STEP_TOLERANCE or gain <= COST_TOLERANCE * cost:
                break
        return s

    def noise(self, s: _State, sigma: dict[str, float]) -> dict[str, float]:
        """Each kind's noise level from the residuals, degrees of freedom less its rows' leverages."""
        r, J, kinds = self.normalised(s, sigma)
        A = self.augmented(s, sigma)[1]
        h = np.einsum("ij,jk,ik->i", J, np.linalg.pinv(A.T @ A), J)
        out = {}
        for kind in dict.fromkeys(kinds):
            rows = np.array([k == kind for k in kinds])
            dof = rows.sum() - h[rows].sum()
            if dof <= 0.5:
                raise DegenerateDataError(f"tracker fit: no degrees of freedom left for the {kind} noise")
            out[kind] = float(np.sqrt(np.sum((r[rows] * sigma[kind]) ** 2) / dof))
        return out


def _exp(xi: FloatArray) -> FloatArray:
    """``(4, 4)`` ``T(exp(ω), v)`` of a step ``(v, ω)`` (:func:`corrected_robot`'s parameterisation)."""
    return make_transform(rotation(xi[3:]), xi[:3])


def _log(R: FloatArray) -> FloatArray:
    """``(N, 3)`` rotation vectors of ``(N, 3, 3)`` rotations."""
    from scipy.spatial.transform import Rotation  # lazy: only 6-D data need it

    return Rotation.from_matrix(R).as_rotvec()


# --- starting values -------------------------------------------------------------------------


def _start(data: TrackerData) -> tuple[FloatArray, FloatArray]:
    """``(T_tracker_base, T_flange_marker)`` of the nominal robot: rigid registrations alternated
    with the marker's linear least squares (the frames' problem is nearly linear once near)."""
    T_bf = data.robot.fk(data.flange, data.Q)
    p_fm = np.zeros(3)
    T_tb = np.eye(4)
    for _ in range(50):
        x_b = T_bf[:, :3, :3] @ p_fm + T_bf[:, :3, 3]
        T_tb = kabsch(x_b, data.p)
        A = (T_tb[:3, :3] @ T_bf[:, :3, :3]).reshape(-1, 3)
        b = (data.p - T_tb[:3, 3] - (T_tb[:3, :3] @ T_bf[:, :3, 3].T).T).ravel()
        new = np.linalg.lstsq(A, b, rcond=None)[0]
        if np.max(np.abs(new - p_fm)) < 1e-12:
            p_fm = new
            break
        p_fm = new
    R_fm = np.eye(3)
    if data.R is not None:
        M = np.sum(np.swapaxes(T_tb[:3, :3] @ T_bf[:, :3, :3], 1, 2) @ data.R, axis=0)
        U, _, Vt = np.linalg.svd(M)
        R_fm = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt
    return T_tb, make_transform(R_fm, p_fm)


# --- fits ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TrackerFit:
    """One model fitted to tracker data.

    Attributes:
        model: a name of :data:`TRACKER_MODELS`.
        T_tracker_base: the robot's base in the tracker's frame.
        T_flange_marker: the marker on the flange (3-D marker: identity rotation, position only).
        corrections: ``(nq, 6)`` joint-origin corrections ``(v, ω)`` (metres, radians).
        parameters: names of the estimated corrections (the kept base set).
        dropped: names of the model's corrections the data cannot see (not estimated).
        sigma: noise level per kind (``position`` metres, ``orientation`` radians).
        position_residuals: ``(N, 3)`` predicted − measured (metres, tracker frame).
        orientation_residuals: ``(N, 3)`` (radians) or ``None``.
    """

    model: str
    T_tracker_base: FloatArray
    T_flange_marker: FloatArray
    corrections: FloatArray
    parameters: tuple[str, ...]
    dropped: tuple[str, ...]
    sigma: dict[str, float]
    position_residuals: FloatArray
    orientation_residuals: FloatArray | None

    def robot(self, nominal: Robot) -> Robot:
        return corrected_robot(nominal, self.corrections)

    def predict(self, data: TrackerData) -> tuple[FloatArray, FloatArray]:
        """``(p (N, 3), R (N, 3, 3))`` the marker's predicted pose in the tracker's frame at ``data``'s postures."""
        T = self.T_tracker_base @ self.robot(data.robot).fk(data.flange, data.Q) @ self.T_flange_marker
        return T[:, :3, 3], T[:, :3, :3]


def select_parameters(
    data: TrackerData, model: str, accuracy: RobotAccuracy
) -> tuple[FloatArray, FloatArray, list[str], list[str]]:
    """The model's corrections the data can see: ``(B (6nq, K), prior (K,), kept, dropped)``.

    At the nominal robot's frames fit, the candidate columns (prior units) projected off the
    frames' span, ranked by pivoted QR; those past the structural rank
    (:data:`~brachycal.calibration.robot.identifiability.STRUCTURAL_RCOND`) are dropped."""
    B_all, names = candidate_columns(data.robot, model, data.flange)
    sd = prior_sd(data.robot, accuracy)
    prior_all = np.array([np.sqrt(np.sum((b * sd) ** 2)) for b in B_all.T])
    if not names:
        return B_all, prior_all, [], []
    frames = fit_tracker(data, "frames", accuracy)
    probe = _Problem(data, B_all, prior_all, _Kinematics(data.robot, data.flange))
    s = _State(frames.T_tracker_base, frames.T_flange_marker, np.zeros(len(names)))
    _, J, _ = probe.normalised(s, frames.sigma)
    J_f, J_c = J[:, : probe.frame_size], J[:, probe.frame_size :] * prior_all
    Q, _ = np.linalg.qr(J_f)
    projected = J_c - Q @ (Q.T @ J_c)
    _, R, pivots = scipy.linalg.qr(projected, mode="economic", pivoting=True)
    diag = np.abs(np.diag(R))
    rank = int(np.sum(diag > diag[0] * STRUCTURAL_RCOND)) if diag.size and diag[0] > 0 else 0
    keep = sorted(pivots[:rank].tolist())
    kept = [names[k] for k in keep]
    dropped = [n for n in names if n not in kept]
    return B_all[:, keep], prior_all[keep], kept, dropped


def fit_tracker(
    data: TrackerData,
    model: str = "frames",
    accuracy: RobotAccuracy = TRACKER_ACCURACY,
    *,
    selection: tuple[FloatArray, FloatArray, list[str], list[str]] | None = None,
) -> TrackerFit:
    """Fit ``model`` (:data:`TRACKER_MODELS`) to ``data`` (module docstring).

    ``selection``: :func:`select_parameters`' result, reused across folds (default: computed).

    Raises:
        DegenerateDataError: too few postures for the frames and noise levels.
    """
    n_rows = len(data.Q) * (6 if data.six_d else 3)
    frame_size = 12 if data.six_d else 9
    if n_rows <= frame_size:
        raise DegenerateDataError(
            f"tracker fit: {len(data.Q)} postures give {n_rows} measurements for {frame_size} frame unknowns"
        )
    if model == "frames":
        B, prior, kept, dropped = np.zeros((6 * data.robot.nq, 0)), np.zeros(0), [], []
    else:
        B, prior, kept, dropped = selection if selection is not None else select_parameters(data, model, accuracy)
    problem = _Problem(data, B, prior, _Kinematics(data.robot, data.flange))
    T_tb, T_fm = _start(data)
    s = _State(T_tb, T_fm, np.zeros(B.shape[1]))
    sigma = dict(START_SIGMA)
    for _ in range(NOISE_ROUNDS):
        s = problem.solve(s, sigma)
        sigma = {**sigma, **problem.noise(s, sigma)}
    s = problem.solve(s, sigma)
    r_p, r_o = problem.residuals(s)
    if not data.six_d:
        sigma.pop("orientation", None)
    return TrackerFit(
        model,
        s.T_tracker_base,
        s.T_flange_marker,
        problem.corrections(s.theta),
        tuple(kept),
        tuple(dropped),
        sigma,
        r_p,
        r_o,
    )


def leave_one_out(
    data: TrackerData,
    model: str,
    accuracy: RobotAccuracy = TRACKER_ACCURACY,
) -> tuple[FloatArray, FloatArray | None]:
    """``(N, 3)`` position errors (metres) and, 6-D, ``(N, 3)`` orientation errors (radians) of
    each posture predicted by a fit of ``model`` made without it (the parameter selection is
    made once on all postures: it is structural, not a fit to the values)."""
    selection = None if model == "frames" else select_parameters(data, model, accuracy)
    N = len(data.Q)
    e_p = np.zeros((N, 3))
    e_o = np.zeros((N, 3)) if data.six_d else None
    for i in range(N):
        keep = np.arange(N) != i
        fit = fit_tracker(data.subset(keep), model, accuracy, selection=selection)
        held = data.subset(~keep)
        p, R = fit.predict(held)
        e_p[i] = p[0] - held.p[0]
        if e_o is not None and held.R is not None:
            e_o[i] = _log(R @ np.swapaxes(held.R, 1, 2))[0]
    return e_p, e_o


@dataclass(frozen=True)
class ModelScore:
    """One model's figures: leave-one-out (headline) and training, per coordinate (mm, deg).

    ``vs_chosen``: the paired comparison with the model chosen before it (mean difference of the
    held-out postures' squared position errors per coordinate, mm², and its standard error);
    ``None`` for the first model."""

    model: str
    parameters: int
    loo_position_mm: float
    training_position_mm: float
    loo_orientation_deg: float | None
    training_orientation_deg: float | None
    loo_errors_m: FloatArray = field(repr=False)
    vs_chosen: tuple[float, float] | None = None


@dataclass(frozen=True)
class TrackerIdentification:
    """The models' scores, the supported model and its fit, and why it was chosen."""

    scores: tuple[ModelScore, ...]
    chosen: str
    reason: str
    fit: TrackerFit

    def summary(self) -> list[str]:
        lines = []
        for s in self.scores:
            o = (
                f", orientation {s.loo_orientation_deg:.3f} deg LOO / {s.training_orientation_deg:.3f} deg training"
                if s.loo_orientation_deg is not None
                else ""
            )
            lines.append(
                f"{s.model:8s} {s.parameters:3d} params: position {s.loo_position_mm:.3f} mm LOO / "
                f"{s.training_position_mm:.3f} mm training per coordinate{o}"
            )
        lines.append(f"chosen: {self.chosen} ({self.reason})")
        return lines


def _per_coordinate_mm(e: FloatArray) -> float:
    return float(np.sqrt(np.mean(e**2)) * 1e3)


def _deg(e: FloatArray | None) -> float | None:
    return None if e is None else float(np.degrees(np.sqrt(np.mean(e**2))))


def identify_from_tracker(
    data: TrackerData,
    accuracy: RobotAccuracy = TRACKER_ACCURACY,
    models: tuple[str, ...] = TRACKER_MODELS,
) -> TrackerIdentification:
    """Score ``models`` (smallest first) by leave-one-out and return the supported one (module
    docstring): each richer model replaces the chosen one only if its held-out mean squared
    position error is lower by more than the paired differences' standard error."""
    scores: list[ModelScore] = []
    fits: dict[str, TrackerFit] = {}
    chosen, chosen_sq = "", np.zeros(0)
    reasons: list[str] = []
    for model in models:
        fit = fit_tracker(data, model, accuracy)
        e_p, e_o = leave_one_out(data, model, accuracy)
        fits[model] = fit
        sq = np.sum(e_p**2, axis=1) / 3 * 1e6  # mm² per coordinate, per held-out posture
        versus = None
        if not chosen:
            chosen, chosen_sq = model, sq
            reasons.append(f"{model}: the smallest model")
        else:
            d = sq - chosen_sq
            mean, se = float(np.mean(d)), float(np.std(d, ddof=1) / np.sqrt(len(d)))
            versus = (mean, se)
            if mean < -se:
                reasons.append(f"{model} beats {chosen} by {-mean:.3g} ± {se:.3g} mm² (LOO)")
                chosen, chosen_sq = model, sq
            else:
                reasons.append(
                    f"{model} not supported: LOO change {mean:+.3g} ± {se:.3g} mm² vs {chosen}, "
                    "not better by more than its standard error"
                )
        scores.append(
            ModelScore(
                model,
                (12 if data.six_d else 9) + len(fit.parameters),
                _per_coordinate_mm(e_p),
                _per_coordinate_mm(fit.position_residuals),
                _deg(e_o),
                _deg(fit.orientation_residuals),
                e_p,
                versus,
            )
        )
    return TrackerIdentification(tuple(scores), chosen, "; ".join(reasons), fits[chosen])
