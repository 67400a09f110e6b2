"""Whole-chain calibration: one least-squares problem over every recorded datum.

Unknowns ``θ``: the needle tip and needle rotation on the right flange (``T_ER_Ntip``), the probe
tip frame on the left flange (``T_EL_Ptip``), the image on the probe (``T_Ptip_I``), the image's
pixel scale (per the image model), and the two reference tips (nuisance). Residuals, each
divided by its group's noise level (metres per coordinate):

- touches: ``T_R_ER @ p_ER_Mtip``, ``T_R_ER @ p_ER_Ntip`` and ``T_R_EL @ p_EL_Ptip`` against the
  reference tip they touched (3 per touch);
- axes: the tip's move p1→p2 (p1→p3) must run along the tool's y (z) axis: its components along
  the tool's other two axes (2 per move; the move's length is not recorded, so not used);
- image samples: the needle tip through the right arm against the annotated pixel through the left
  arm, ``T_R_ER p_ER_Ntip − T_R_EL T_EL_Ptip T_Ptip_I (u s_u, v s_v, 0)`` (3 per image).

Image models: ``rigid`` (the scanner's spacing), ``similarity`` (one scale), ``scaled_uv`` (a scale
per axis) and ``sound_speed`` (the physical model: lateral spacing as the scanner says, depth
spacing times c / 1540 m/s, with the speed of sound c estimated).

Two stages, both :func:`scipy.optimize.least_squares` from the sequential result:

1. **Robust stage** (finds gross errors): soft-L1 loss on the normalised residuals, each group's
   noise level re-estimated from its residuals by the median absolute deviation (× 1.4826, with
   the degrees-of-freedom correction below). Image samples whose 3D residual exceeds
   :data:`OUTLIER_THRESHOLD` × √3 σ_image are flagged: for Gaussian noise ``|r|²/σ²`` is χ²₃, and
   3 × 3.5² = 36.75 puts a clean sample past it with probability 5e-8 (3e-6 per session of 64),
   while a 15 px annotation mistake (2.9 mm) sits at about 8 × √3 σ_image.
2. **Final stage** (the estimate and its covariance): the flagged samples are left out and the
   problem is solved by plain least squares (the efficient estimator for the remaining,
   Gaussian-like noise; the soft-L1 estimate's variance is E[ψ²]/E[ψ']² = 1.08 times that, while
   its Gauss–Newton covariance, ``(E[ψ'] JᵀJ)⁻¹`` with E[ψ'] = 0.56, states 1.77 times: SDs 1.28×
   too wide, as the speed of sound's were). Each group's noise level is its residual sum
   of squares over its residual degrees of freedom ``n_g − Σ_{i∈g} h_ii`` (``h`` the leverages
   of the weighted problem: the unbiased estimate for a linear model), iterated with the weights.
   The covariance is ``(JᵀJ)⁻¹`` of the Jacobian of the normalised residuals. A group with fewer
   than :data:`MIN_NOISE_DOF` residual degrees of freedom cannot estimate its own noise (its
   relative error would exceed 25 %): the axes moves (8 residuals, 6 rotations: 2 degrees of
   freedom) take the touches' level (the same robot placing the same tools), reported as assumed.
   A group whose residuals are below :data:`RESOLUTION_M` is reported as below resolution.

Conditioning (refusals with :class:`~brachycal.errors.DegenerateDataError`): see
:func:`check_conditioning`.

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

The robot model's own error (consider covariance, :class:`RobotAccuracy`): the physical robot's
joint origins differ from the URDF's. Where the session's data see it (the spread of touches
across poses, of images across the cube) it is in the noise levels; where they cannot (e.g. an
offset of the left arm against the right one, which the probe-tip touches cannot tell from the
probe tip) it shifts the estimate without any trace in the residuals. With a stated accuracy —
each joint's origin off by a small motion ``c_j`` (translation ``v``, rotation ``ω`` about the
origin's own axes, plus a zero offset about the joint axis: the model
:func:`brachycal.simulation.twin.physical_kinematics` draws from), ``Σ_c`` its covariance — the
estimate's sensitivity is ``S = (JᵀJ)⁻¹ Jᵀ J_c`` (``J_c`` the normalised residuals' Jacobian with
respect to the 6 components of every ``c_j``, :func:`robot_jacobian`) and the stated covariance
``(JᵀJ)⁻¹ + S Σ_c Sᵀ``. (Sign: ``c`` is the physical robot's deviation from the model; at the true
parameters the model's residuals are ``−J_c c``, so the estimate moves by ``+(JᵀJ)⁻¹Jᵀ J_c c``;
the sign matters for the landing error, where this shift and ``c``'s direct effect partly cancel.)
``benchmarks/chain_checks.py`` measures the coverage on the twin.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from brachycal.calibration.image_to_probe import ImageCalibration
from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.sequential import CalibrationResult
from brachycal.data.session import Session
from brachycal.errors import DegenerateDataError, InputError
from brachycal.imaging import SCANNER_SOUND_SPEED_M_S
from brachycal.model.names import LEFT_FLANGE, RIGHT_FLANGE
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray, make_transform, transform_points
from brachycal.validate import check_range

SCANNER_SOUND_SPEED = SCANNER_SOUND_SPEED_M_S  # one home: brachycal.imaging
MODELS = ("rigid", "similarity", "scaled_uv", "sound_speed")
#: Starting noise levels (metres per coordinate) of the residual groups; also the level assumed
#: for a group with too few residual degrees of freedom to estimate its own.
INITIAL_SIGMA = {"touch": 1e-4, "axes": 1e-4, "image": 3e-4}
GROUPS = ("touch", "axes", "image")
OUTLIER_THRESHOLD = 3.5
#: Most least-squares solves of the final stage while its weights (noise levels) settle; they
#: settle to 1e-6 in 3-5 (each solve's leverages and residuals barely move the next).
NOISE_ITERATIONS = 20
#: Fewest residual degrees of freedom ν from which a group's noise level is estimated: the
#: relative SD of the estimate is about 1/√(2ν), 25 % at ν = 8.
MIN_NOISE_DOF = 8.0
#: One micrometre: below anything this set-up resolves (encoder noise alone is ~20 µm at 1 m). A
#: group's noise level is not taken below it (it weights the group), and a group whose residual
#: scale is at it is reported as below resolution, not as a measured noise level.
RESOLUTION_M = 1e-6
#: Reciprocal condition number (smallest over largest singular value of the normalised Jacobian
#: with unit-norm columns) below which a combination of the unknowns counts as undetermined. The
#: Jacobian is analytic, exact to rounding: an exactly degenerate session (every sample at one
#: pose) measures ~1e-17, sessions that span the prostate cube 7e-3–2e-2 (twin seeds 0–19,
#: `benchmarks/chain_checks.py`); 1e-8 sits far from both, and the grey zone between is left to
#: the rotation check below. (Joint offsets' columns come from forward differences, relative
#: errors ~1e-7, but their prior keeps them determined whatever the data.)
RCOND_LIMIT = 1e-8
#: Largest accepted SD (rad) of a fitted rotation (largest axis of its 3×3 covariance). The
#: intervals and the predicted landing error are linearisations; the second-order term of a
#: rotation error δ is δ²/2, i.e. a fraction δ/2 of the first-order one. At SD 0.05 rad (2.9°)
#: the 95 % range reaches 0.1 rad, where the linearisation is off by 5 %: beyond it, the data do
#: not determine the rotation well enough for any stated uncertainty to hold. Sessions that span
#: the prostate cube measure 0.2–0.5° (twin seeds 0–19, `benchmarks/chain_checks.py`).
ROTATION_SD_LIMIT = 0.05


#: Largest stated per-joint placement error (typo guards, 100 times issue 19's 0.1 mm / 0.01° for
#: real arms): beyond them the URDF does not describe the robot and no linearisation holds.
MAX_ROBOT_TRANSLATION_SD_M = 1e-2
MAX_ROBOT_ROTATION_SD_RAD = np.radians(1.0)
MAX_ENCODER_SD_RAD = 1e-2


@dataclass(frozen=True)
class RobotAccuracy:
    """How far the physical robot is from its URDF, as stated by the user (not estimated).

    Per joint, independent and zero-mean: the joint's origin is off by a translation of
    ``translation_sd_m`` SD per axis (metres) and a rotation of ``rotation_sd_rad`` SD per axis
    (radians, about the origin's own axes), and its zero by ``rotation_sd_rad`` SD about its axis
    (the model the twin draws its physical robot from). ``encoder_sd_rad`` is the SD of each joint
    reading (radians): it enters the landing error when aiming (the probe arm's and torso's
    readings place the target).

    Defaults (:data:`DEFAULT_ROBOT_ACCURACY`): the twin's well-built arm, 0.03 mm / 0.003° per
    joint and 2e-5 rad per reading. The vendor states ±0.1 mm repeatability (not accuracy), and
    arms off their URDF by 0.1 mm / 0.01° per joint are common (issue 19): state the arm's own
    figures when known; a figure stated too small gives intervals too narrow.

    Raises:
        InputError: a value is negative, not finite, or beyond the typo guards above.
    """

    translation_sd_m: float = 3e-5
    rotation_sd_rad: float = float(np.radians(0.003))
    encoder_sd_rad: float = 2e-5
    source: str = "default: the twin's well-built arm (0.03 mm / 0.003 deg per joint, 2e-5 rad per reading)"

    def __post_init__(self) -> None:
        check_range(
            self.translation_sd_m, "robot accuracy (translation SD)", low=0.0, high=MAX_ROBOT_TRANSLATION_SD_M, unit="m"
        )
        check_range(
            self.rotation_sd_rad, "robot accuracy (rotation SD)", low=0.0, high=MAX_ROBOT_ROTATION_SD_RAD, unit="rad"
        )
        check_range(self.encoder_sd_rad, "robot accuracy (encoder SD)", low=0.0, high=MAX_ENCODER_SD_RAD, unit="rad")

    def covariance(self, robot: Robot) -> FloatArray:
        """``(6 nq, 6 nq)`` covariance of the joints' origin errors ``(v, ω)`` in :func:`robot_jacobian`'s
        order (metres², radians²): the zero offset adds ``rotation_sd²`` along each joint's axis."""
        blocks = []
        for name in robot.joint_names:
            axis = robot.joint_axis(name)
            block = np.zeros((6, 6))
            block[:3, :3] = self.translation_sd_m**2 * np.eye(3)
            block[3:, 3:] = self.rotation_sd_rad**2 * (np.eye(3) + np.outer(axis, axis))
            blocks.append(block)
        out = np.zeros((6 * len(blocks), 6 * len(blocks)))
        for j, block in enumerate(blocks):
            out[6 * j : 6 * j + 6, 6 * j : 6 * j + 6] = block
        return out

    def as_json(self) -> dict[str, object]:
        return {
            "joint_translation_sd_mm": self.translation_sd_m * 1e3,
            "joint_rotation_sd_deg": float(np.degrees(self.rotation_sd_rad)),
            "encoder_sd_deg": float(np.degrees(self.encoder_sd_rad)),
            "source": self.source,
        }


DEFAULT_ROBOT_ACCURACY = RobotAccuracy()


#: Blocks of the parameter vector: name → (first index, length) for the fixed part; the scale
#: factors and joint offsets follow (see :meth:`ParameterLayout.blocks`).
_FIXED_BLOCKS = {
    "p_ER_Ntip": (0, 3),
    "rot_ER_Ntip": (3, 3),
    "rot_EL_Ptip": (6, 3),
    "p_EL_Ptip": (9, 3),
    "rot_Ptip_I": (12, 3),
    "p_Ptip_I": (15, 3),
    "p_R_Rtip1": (18, 3),
    "p_R_Rtip2": (21, 3),
}
#: What each block is, and the session file whose data determine it (for refusals).
BLOCK_LABELS = {
    "p_ER_Ntip": ("the needle tip", "touches.csv"),
    "rot_ER_Ntip": ("the needle rotation", "axes.csv"),
    "rot_EL_Ptip": ("the probe rotation", "axes.csv"),
    "p_EL_Ptip": ("the probe tip", "touches.csv"),
    "rot_Ptip_I": ("the image rotation", "samples.csv"),
    "p_Ptip_I": ("the image origin", "samples.csv"),
    "p_R_Rtip1": ("reference tip rtip1", "touches.csv"),
    "p_R_Rtip2": ("reference tip rtip2", "touches.csv"),
    "scale": ("the pixel scale", "samples.csv"),
    "joint_offsets": ("the joint offsets", "samples.csv"),
}
ROTATIONS = ("rot_ER_Ntip", "rot_EL_Ptip", "rot_Ptip_I")


@dataclass(frozen=True)
class ChainData:
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
    def of(cls, session: Session, robot: Robot, offsets: FloatArray | None = None) -> ChainData:
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

    @cached_property
    def touch_T(self) -> FloatArray:
        """``(M, 4, 4)`` flange poses of every touch: top-model, needle, probe; rtip1 then rtip2."""
        return np.concatenate([T for touches in (self.top, self.needle, self.probe) for _, T in touches])

    @cached_property
    def touch_tool(self) -> np.ndarray:
        """``(M,)`` which tool each touch holds: 0 top-model, 1 needle, 2 probe."""
        return np.concatenate(
            [np.full(len(T), i) for i, touches in enumerate((self.top, self.needle, self.probe)) for _, T in touches]
        )

    @cached_property
    def touch_ref(self) -> np.ndarray:
        """``(M,)`` which reference tip each touch touched: 0 rtip1, 1 rtip2."""
        return np.concatenate(
            [np.full(len(T), k) for touches in (self.top, self.needle, self.probe) for k, T in touches]
        )

    @property
    def n_touch_rows(self) -> int:
        return 3 * len(self.touch_tool)

    def group_rows(self, n_images: int) -> dict[str, slice]:
        """Rows of each residual group in :func:`chain_residuals` with ``n_images`` samples used."""
        t = self.n_touch_rows
        return {"touch": slice(0, t), "axes": slice(t, t + 8), "image": slice(t + 8, t + 8 + 3 * n_images)}


@dataclass(frozen=True)
class ParameterLayout:
    model: str
    offset_joints: tuple[int, ...] = ()

    @property
    def n_scale(self) -> int:
        return {"rigid": 0, "similarity": 1, "scaled_uv": 2, "sound_speed": 1}[self.model]

    @property
    def size(self) -> int:
        return 24 + self.n_scale + len(self.offset_joints)

    def blocks(self) -> dict[str, slice]:
        """Parameter name → its slice of the parameter vector (the one place that knows the layout)."""
        out = {name: slice(start, start + n) for name, (start, n) in _FIXED_BLOCKS.items()}
        out["scale"] = slice(24, 24 + self.n_scale)
        out["joint_offsets"] = slice(24 + self.n_scale, self.size)
        return out

    def offsets(self, x: FloatArray, nq: int) -> FloatArray:
        out = np.zeros(nq)
        out[list(self.offset_joints)] = x[self.blocks()["joint_offsets"]]
        return out

    def unpack(self, x: FloatArray, base: dict[str, FloatArray], nominal_spacing: FloatArray):
        b = self.blocks()
        T_ER_Ntip = make_transform(_rotation(x[b["rot_ER_Ntip"]]) @ base["R_ER_Ntip"], x[b["p_ER_Ntip"]])
        T_EL_Ptip = make_transform(_rotation(x[b["rot_EL_Ptip"]]) @ base["R_EL_Ptip"], x[b["p_EL_Ptip"]])
        T_Ptip_I = make_transform(_rotation(x[b["rot_Ptip_I"]]) @ base["R_Ptip_I"], x[b["p_Ptip_I"]])
        rtips = np.vstack([x[b["p_R_Rtip1"]], x[b["p_R_Rtip2"]]])
        scale = x[b["scale"]]
        if self.model == "rigid":
            spacing = nominal_spacing
        elif self.model == "similarity":
            spacing = nominal_spacing * scale[0]
        elif self.model == "scaled_uv":
            spacing = nominal_spacing * scale
        else:  # sound_speed: scale[0] is c / 1540
            spacing = nominal_spacing * [1.0, scale[0]]
        return T_ER_Ntip, T_EL_Ptip, T_Ptip_I, rtips, spacing


def _rotation(rotvec: FloatArray) -> FloatArray:
    """``(3, 3)`` rotation of a rotation vector (Rodrigues; scipy's Rotation costs 20× more per call)."""
    angle = float(np.sqrt(rotvec @ rotvec))
    if angle == 0.0:
        return np.eye(3)
    K = np.array([[0.0, -rotvec[2], rotvec[1]], [rotvec[2], 0.0, -rotvec[0]], [-rotvec[1], rotvec[0], 0.0]])
    half = 0.5 * angle  # (1 − cos a)/a² = ½ (sin(a/2)/(a/2))²: no cancellation at the tiny angles of a Jacobian step
    return np.eye(3) + np.sin(angle) / angle * K + 0.5 * (np.sin(half) / half) ** 2 * K @ K


def finite_difference_steps(x: FloatArray) -> FloatArray:
    """Forward-difference steps for Jacobians at ``x``: 1e-7, relative for large entries."""
    return 1e-7 * np.maximum(1.0, np.abs(x))


#: Axes moves: (point, the column of the tool's rotation it moves along, the two columns its
#: residual is measured along).
_AXES_MOVES = ((1, 1, [0, 2]), (2, 2, [0, 1]))


def chain_residuals(
    x: FloatArray,
    layout: ParameterLayout,
    data: ChainData,
    base: dict,
    sigma: dict[str, float],
    samples: np.ndarray,
) -> FloatArray:
    T_ER_Ntip, T_EL_Ptip, T_Ptip_I, rtips, spacing = layout.unpack(x, base, data.spacing_m)
    p_tools = np.stack([data.p_ER_Mtip, T_ER_Ntip[:3, 3], T_EL_Ptip[:3, 3]])[data.touch_tool]
    touch = np.einsum("nij,nj->ni", data.touch_T[:, :3, :3], p_tools) + data.touch_T[:, :3, 3] - rtips[data.touch_ref]
    parts = [touch.ravel() / sigma["touch"]]
    for T_axes, T_tool in ((data.needle_axes, T_ER_Ntip), (data.probe_axes, T_EL_Ptip)):
        tips = transform_points(T_axes, T_tool[:3, 3])
        R_tool = T_axes[0, :3, :3] @ T_tool[:3, :3]
        for point, _, across in _AXES_MOVES:
            parts.append(R_tool[:, across].T @ (tips[point] - tips[0]) / sigma["axes"])
    parts.append(_image_residuals(data, T_ER_Ntip, T_EL_Ptip @ T_Ptip_I, spacing)[samples].ravel() / sigma["image"])
    return np.concatenate(parts)


def _image_residuals(data: ChainData, T_ER_Ntip: FloatArray, T_EL_I: FloatArray, spacing: FloatArray) -> FloatArray:
    p_I = np.column_stack([data.uv_px * spacing, np.zeros(len(data.uv_px))])
    return transform_points(data.T_R_ER, T_ER_Ntip[:3, 3]) - transform_points(data.T_R_EL @ T_EL_I, p_I)


def _skew(v: FloatArray) -> FloatArray:
    """``(..., 3, 3)`` cross-product matrices of ``(..., 3)`` vectors: ``skew(a) @ b = a × b``."""
    v = np.asarray(v, dtype=float)
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    out[..., 1, 0], out[..., 2, 0], out[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return out


def _left_jacobian(rotvec: FloatArray) -> FloatArray:
    """``(3, 3)`` left Jacobian of SO(3): ``exp(ω + dω) ≈ exp(J_l(ω) dω) exp(ω)``."""
    angle = float(np.sqrt(rotvec @ rotvec))
    K = _skew(rotvec)
    if angle < 1e-6:  # series: the next terms are below 1e-13
        return np.eye(3) + 0.5 * K + K @ K / 6.0
    half = 0.5 * angle
    return np.eye(3) + 0.5 * (np.sin(half) / half) ** 2 * K + (angle - np.sin(angle)) / angle**3 * K @ K


def chain_jacobian(
    x: FloatArray, layout: ParameterLayout, data: ChainData, base: dict, sigma: dict[str, float], samples: np.ndarray
) -> FloatArray:
    """Analytic Jacobian ``(M, P)`` of :func:`chain_residuals` (layouts without joint offsets).

    A rotation ``R = exp(ω) R_base`` moves a vector ``b`` by ``d(R b) = −[R b]× J_l(ω) dω``.
    """
    b = layout.blocks()
    T_ER_Ntip, T_EL_Ptip, T_Ptip_I, _, spacing = layout.unpack(x, base, data.spacing_m)
    R_P, R_I = T_EL_Ptip[:3, :3], T_Ptip_I[:3, :3]
    rows = data.group_rows(int(np.count_nonzero(samples)))
    J = np.zeros((rows["image"].stop, layout.size))
    # Touches: R p_tool + t − rtip.
    touch = np.zeros((len(data.touch_tool), 3, layout.size))
    R_touch = data.touch_T[:, :3, :3]
    for tool, name in ((1, "p_ER_Ntip"), (2, "p_EL_Ptip")):
        touch[data.touch_tool == tool, :, b[name]] = R_touch[data.touch_tool == tool]
    for k, name in enumerate(("p_R_Rtip1", "p_R_Rtip2")):
        touch[data.touch_ref == k, :, b[name]] = -np.eye(3)
    J[rows["touch"]] = touch.reshape(-1, layout.size) / sigma["touch"]
    # Axes moves: (R_a0 R_tool e_c) · (tip_i − tip_0) for the two columns c across the move.
    axes = []
    for T_axes, T_tool, rot, tip in (
        (data.needle_axes, T_ER_Ntip, "rot_ER_Ntip", "p_ER_Ntip"),
        (data.probe_axes, T_EL_Ptip, "rot_EL_Ptip", "p_EL_Ptip"),
    ):
        R_a, t_a = T_axes[:, :3, :3], T_axes[:, :3, 3]
        R_tool, p_tool = T_tool[:3, :3], T_tool[:3, 3]
        J_l = _left_jacobian(x[b[rot]])
        for point, _, across in _AXES_MOVES:
            move = (R_a[point] - R_a[0]) @ p_tool + t_a[point] - t_a[0]
            w = R_a[0].T @ move
            for c in across:
                v = R_tool[:, c]
                row = np.zeros(layout.size)
                row[b[tip]] = (R_a[0] @ v) @ (R_a[point] - R_a[0])
                row[b[rot]] = np.cross(v, w) @ J_l
                axes.append(row)
    J[rows["axes"]] = np.array(axes) / sigma["axes"]
    # Images: R_ER p_N + t_ER − R_EL (R_P (R_I p_I + t_I) + t_P) − t_EL.
    uv = data.uv_px[samples]
    R_ER, R_EL = data.T_R_ER[samples, :3, :3], data.T_R_EL[samples, :3, :3]
    p_I = np.column_stack([uv * spacing, np.zeros(len(uv))])
    R_I_p = p_I @ R_I.T
    w = R_I_p + T_Ptip_I[:3, 3]
    image = np.zeros((len(uv), 3, layout.size))
    image[:, :, b["p_ER_Ntip"]] = R_ER
    image[:, :, b["p_EL_Ptip"]] = -R_EL
    image[:, :, b["p_Ptip_I"]] = -R_EL @ R_P
    image[:, :, b["rot_EL_Ptip"]] = R_EL @ _skew(w @ R_P.T) @ _left_jacobian(x[b["rot_EL_Ptip"]])
    image[:, :, b["rot_Ptip_I"]] = R_EL @ R_P @ _skew(R_I_p) @ _left_jacobian(x[b["rot_Ptip_I"]])
    nominal = data.spacing_m
    du = np.column_stack([uv[:, 0] * nominal[0], np.zeros((len(uv), 2))])  # ∂p_I per unit of a u scale
    dv = np.column_stack([np.zeros(len(uv)), uv[:, 1] * nominal[1], np.zeros(len(uv))])
    dp = {"rigid": [], "similarity": [du + dv], "scaled_uv": [du, dv], "sound_speed": [dv]}[layout.model]
    R_total = R_EL @ (R_P @ R_I)
    for k, d in enumerate(dp):
        image[:, :, b["scale"].start + k] = -np.einsum("nij,nj->ni", R_total, d)
    J[rows["image"]] = image.reshape(-1, layout.size) / sigma["image"]
    return J


def joint_twists(robot: Robot, Q: FloatArray, flange: str) -> FloatArray:
    """``(N, nq, 6, 6)``: how a small motion of each joint's origin moves ``flange``.

    ``W[n, j] @ (v, ω)`` is the world twist ``(v_w, ω_w)`` (metres, radians, in ``base_link``) of
    the flange at configuration ``Q[n]`` when joint ``j``'s origin is moved by ``exp((v, ω))``
    on its right (in the origin's own frame, before the joint's turn: the parameterisation of
    :meth:`Robot.with_joint_origins` and of the twin's physical robot): any point ``p`` fixed to the
    flange moves by ``v_w + ω_w × p``. Zero for joints not between the base and the flange. A zero
    offset of joint ``j`` is the motion ``(0, axis_j)``.
    """
    import pinocchio as pin

    model = robot.model
    data = model.createData()
    support = set(model.supports[model.frames[robot.frame_id(flange)].parentJoint])
    ids = [model.getJointId(name) for name in robot.joint_names]
    Q = np.atleast_2d(np.asarray(Q, dtype=float))
    out = np.zeros((len(Q), len(ids), 6, 6))
    for n, q in enumerate(robot.to_pinocchio(Q)):
        pin.forwardKinematics(model, data, q)
        for j, jid in enumerate(ids):
            if jid not in support:
                continue
            T = data.oMi[model.parents[jid]] * model.jointPlacements[jid]  # the origin's frame, before the turn
            R, t = T.rotation, T.translation
            out[n, j, :3, :3] = R
            out[n, j, :3, 3:] = _skew(t) @ R  # v_w = R v + t × (R ω)
            out[n, j, 3:, 3:] = R
    return out


def _moved(T: FloatArray, twist: FloatArray, step: float) -> FloatArray:
    """``(n, 4, 4)`` poses ``T`` moved by the world twists ``step · twist`` ``(n, 6)`` (first order exact)."""
    from scipy.spatial.transform import Rotation

    turn = Rotation.from_rotvec(step * twist[:, 3:]).as_matrix()
    out = T.copy()
    out[:, :3, :3] = turn @ T[:, :3, :3]
    out[:, :3, 3] = np.einsum("nij,nj->ni", turn, T[:, :3, 3]) + step * twist[:, :3]
    return out


#: Step of the central differences in :func:`robot_jacobian` (metres / radians of origin motion).
#: Curvature error ~step² (1e-12 relative), rounding ~1e-16 m / (1e-6 · 1e-4 m noise level) ~1e-6
#: relative of the smallest columns; both far below the 1e-3 agreement the tests ask of it.
ROBOT_STEP = 1e-6


def _robot_jacobian(
    session: Session,
    robot: Robot,
    layout: ParameterLayout,
    x: FloatArray,
    base: dict,
    sigma: dict[str, float],
    keep: np.ndarray,
) -> FloatArray:
    """``(M, 6 nq)`` Jacobian of :func:`chain_residuals` with respect to every joint's origin motion
    ``(v, ω)`` (joint-major, :func:`joint_twists`' order), by central differences of the flange
    poses moved by :func:`joint_twists` (the residuals themselves are evaluated exactly)."""
    offsets = layout.offsets(x, robot.nq)
    data = ChainData.of(session, robot, offsets)

    def twists(q: FloatArray, flange: str) -> FloatArray:
        return joint_twists(robot, np.atleast_2d(q) + offsets, flange)

    refs = ("rtip1", "rtip2")
    W: dict[str, Any] = {  # per data group: twists (an array, or one per reference tip)
        "top": [twists(session.touches["top_model", r].q, RIGHT_FLANGE) for r in refs],
        "needle": [twists(session.touches["needle", r].q, RIGHT_FLANGE) for r in refs],
        "probe": [twists(session.touches["probe", r].q, LEFT_FLANGE) for r in refs],
        "needle_axes": twists(np.array([session.axes["needle"][p] for p in ("p1", "p2", "p3")]), RIGHT_FLANGE),
        "probe_axes": twists(np.array([session.axes["probe"][p] for p in ("p1", "p2", "p3")]), LEFT_FLANGE),
        "T_R_ER": twists(session.samples_q, RIGHT_FLANGE),
        "T_R_EL": twists(session.samples_q, LEFT_FLANGE),
    }

    def moved(j: int, d: int, step: float) -> ChainData:
        def touches(name: str) -> list[tuple[int, FloatArray]]:
            return [(k, _moved(T, w[:, j, :, d], step)) for (k, T), w in zip(getattr(data, name), W[name], strict=True)]

        return replace(
            data,
            top=touches("top"),
            needle=touches("needle"),
            probe=touches("probe"),
            **{
                name: _moved(getattr(data, name), W[name][:, j, :, d], step)
                for name in ("needle_axes", "probe_axes", "T_R_ER", "T_R_EL")
            },
        )

    columns = []
    for j in range(robot.nq):
        for d in range(6):
            plus = chain_residuals(x, layout, moved(j, d, ROBOT_STEP), base, sigma, keep)
            minus = chain_residuals(x, layout, moved(j, d, -ROBOT_STEP), base, sigma, keep)
            columns.append((plus - minus) / (2 * ROBOT_STEP))
    return np.column_stack(columns)


def robot_jacobian(session: Session, robot: Robot, fit: ChainFit) -> FloatArray:
    """``(M, 6 nq)`` ``J_c``: the fit's normalised residuals (its final problem: its noise levels,
    its samples) differentiated with respect to every joint's origin motion ``(v, ω)`` (metres,
    radians; joint-major in ``robot.joint_names`` order; see :func:`joint_twists`)."""
    layout = ParameterLayout(fit.model, tuple(robot.joint_names.index(n) for n in fit.joint_offsets_rad))
    return _robot_jacobian(session, robot, layout, fit.x, fit.base, fit.sigma_m, ~fit.outliers)


@dataclass(frozen=True)
class NoiseLevel:
    """A residual group's noise level and where it comes from.

    Attributes:
        sd_m: noise SD per coordinate, metres (the weight the group gets).
        dof: residual degrees of freedom of the group (its rows minus its leverages).
        source: ``"residuals"`` (estimated from them), ``"assumed"`` (too few degrees of freedom;
            see ``note``) or ``"below resolution"`` (the residuals are under :data:`RESOLUTION_M`).
        note: one line a person can read.
    """

    sd_m: float
    dof: float
    source: str
    note: str


@dataclass(frozen=True)
class Conditioning:
    """How well the final fit's data determine its unknowns.

    Attributes:
        rcond: reciprocal condition number of the normalised Jacobian with unit-norm columns.
        rotation_sd_rad: each fitted rotation's largest SD (rad).
    """

    rcond: float
    rotation_sd_rad: dict[str, float]


@dataclass(frozen=True)
class ChainFit:
    """One solved chain problem.

    Attributes:
        model: the image model.
        T_ER_Ntip, T_EL_Ptip: ``(4, 4)``.
        image: the image calibration (rigid ``T_Ptip_I`` and spacing).
        sound_speed_m_s: the implied speed of sound (from the depth scale; None for rigid).
        p_R_Rtip: ``(2, 3)`` reference tips.
        sigma_m: noise level per residual group (touch, axes, image), metres per coordinate.
        covariance: ``(P, P)`` of the parameter vector (metres, radians, scale factors): the session's
            noise ``(JᵀJ)⁻¹`` of the final fit plus, with a stated robot accuracy, the robot model's
            own error ``S Σ_c Sᵀ`` (module docstring).
        x: ``(P,)`` parameter vector (increments of rotations about the starting rotations).
        outliers: ``(N,)`` image samples flagged as gross errors and left out of the final fit.
        image_residuals: ``(N, 3)`` per-sample residual of the final fit, metres (flagged included).
        joint_offsets_rad: estimated joint zero offsets (empty unless asked for).
        noise: per group, the noise level with its degrees of freedom and source.
        conditioning: the conditioning figures of the final fit.
        noise_covariance: ``(P, P)`` the session's noise part ``(JᵀJ)⁻¹`` alone.
        robot_sensitivity: ``(P, 6 nq)`` ``S = ∂x̂/∂c``: how the estimate moves with the physical
            joints' origin errors ``c`` (None without a stated robot accuracy).
        robot_covariance: ``(6 nq, 6 nq)`` ``Σ_c`` of the stated accuracy (None without one).
        robot_accuracy: the stated accuracy (None: the robot term was not computed).
        noise_share: per group, the fraction of its residual variance left to the session's noise
            once the stated robot accuracy's expected part is taken out (:func:`_noise_share`).
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
    noise: dict[str, NoiseLevel] = field(default_factory=dict)
    conditioning: Conditioning | None = None
    noise_covariance: FloatArray | None = None
    robot_sensitivity: FloatArray | None = None
    robot_covariance: FloatArray | None = None
    robot_accuracy: RobotAccuracy | None = None
    noise_share: dict[str, float] = field(default_factory=dict)

    def offsets(self, joint_names: tuple[str, ...]) -> FloatArray:
        """``(nq,)`` estimated joint zero offsets (zeros unless estimated), radians."""
        return np.array([self.joint_offsets_rad.get(name, 0.0) for name in joint_names])

    def parameter_sd(self) -> FloatArray:
        """``(P,)`` SD of each parameter (metres, radians, scale factors)."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    def T_EL_I(self, x: FloatArray | None = None) -> FloatArray:
        """``(4, 4)`` the image frame on the left flange, ``T_EL_Ptip @ T_Ptip_I``, at ``x`` (default the
        estimate): what the image samples determine, whatever the probe-tip frame's convention."""
        layout = ParameterLayout(self.model)
        at = self.x if x is None else np.asarray(x, dtype=float)
        _, T_EL_Ptip, T_Ptip_I, _, _ = layout.unpack(at[: layout.size], self.base, np.ones(2))
        return T_EL_Ptip @ T_Ptip_I

    def block(self, name: str) -> slice:
        """The slice of parameter ``name`` (see :data:`BLOCK_LABELS`) in ``x`` and ``covariance``."""
        s = ParameterLayout(self.model).blocks()[name]
        return slice(s.start, len(self.x)) if name == "joint_offsets" else s

    def noise_text(self) -> str:
        """The noise levels in one line, each with its source."""
        names = {"touch": "touches", "axes": "axes moves", "image": "images"}
        return "; ".join(f"{names[g]} {n.note}" for g, n in self.noise.items()) or ", ".join(
            f"{names[g]} {v * 1e3:.3f} mm" for g, v in self.sigma_m.items()
        )


def _start(initial: CalibrationResult, layout: ParameterLayout, nominal_spacing: FloatArray) -> tuple[FloatArray, dict]:
    image = initial.image.get("scaled_uv") or next(iter(initial.image.values()))
    base = {
        "R_ER_Ntip": initial.T_ER_Ntip[:3, :3],
        "R_EL_Ptip": initial.T_EL_Ptip[:3, :3],
        "R_Ptip_I": image.T_Ptip_I[:3, :3],
    }
    b = layout.blocks()
    x = np.zeros(layout.size)
    x[b["p_ER_Ntip"]] = initial.T_ER_Ntip[:3, 3]
    x[b["p_EL_Ptip"]] = initial.T_EL_Ptip[:3, 3]
    x[b["p_Ptip_I"]] = image.T_Ptip_I[:3, 3]
    x[b["p_R_Rtip1"]], x[b["p_R_Rtip2"]] = initial.p_R_Rtip["rtip1"], initial.p_R_Rtip["rtip2"]
    ratio = image.spacing_m / nominal_spacing
    if layout.model == "similarity":
        x[b["scale"]] = ratio.mean()
    elif layout.model == "scaled_uv":
        x[b["scale"]] = ratio
    elif layout.model == "sound_speed":
        x[b["scale"]] = ratio[1]
    return x, base


#: Prior SD of an estimated joint zero offset (rad): keeps weakly excited offsets near zero.
OFFSET_PRIOR_SD = np.radians(0.01)


def leverages(J: FloatArray) -> FloatArray:
    """Diagonal of the hat matrix ``J (JᵀJ)⁺ Jᵀ`` (rows' leverages), from an SVD of ``J``."""
    norms = np.linalg.norm(J, axis=0)
    live = norms > 0  # the hat matrix does not depend on the columns' scales: equilibrate them
    U, s, _ = np.linalg.svd(J[:, live] / norms[live], full_matrices=False)
    rank = s > s[0] * RCOND_LIMIT if s.size and s[0] > 0 else np.zeros(s.size, dtype=bool)
    return np.sum(U[:, rank] ** 2, axis=1)


def _noise_levels(
    normalised: FloatArray,
    J: FloatArray,
    rows: dict[str, slice],
    sigma: dict[str, float],
    robust: bool,
) -> dict[str, NoiseLevel]:
    """Each group's noise level from its residuals, with the degrees-of-freedom correction.

    ``normalised`` and ``J`` are the residuals and Jacobian of the weighted problem (rows divided
    by ``sigma``). Final stage: ``σ_g² = Σ_g r_raw² / (n_g − Σ_g h_ii)``; robust stage: the same
    correction applied to 1.4826 × the median absolute residual. Groups with fewer than
    :data:`MIN_NOISE_DOF` residual degrees of freedom take an assumed level (see the module).
    """
    h = leverages(J)
    out: dict[str, NoiseLevel] = {}
    for g in GROUPS:
        raw = normalised[rows[g]] * sigma[g]
        dof = float(raw.size - h[rows[g]].sum())
        if dof < MIN_NOISE_DOF:
            continue
        if robust:
            scale = 1.4826 * float(np.median(np.abs(raw))) * np.sqrt(raw.size / dof)
        else:
            scale = float(np.sqrt(np.sum(raw**2) / dof))
        if scale < RESOLUTION_M:
            note = f"below {RESOLUTION_M * 1e3:.3f} mm (resolution)"
            out[g] = NoiseLevel(RESOLUTION_M, dof, "below resolution", note)
        else:
            out[g] = NoiseLevel(scale, dof, "residuals", f"{scale * 1e3:.3f} mm ({dof:.0f} residual dof)")
    for g in GROUPS:
        if g in out:
            continue
        dof = float(normalised[rows[g]].size - h[rows[g]].sum())
        if g == "axes" and "touch" in out:
            level, why = out["touch"].sd_m, "the touches' level"
        else:
            level, why = INITIAL_SIGMA[g], "the prior level"
        out[g] = NoiseLevel(level, dof, "assumed", f"{level * 1e3:.3f} mm assumed ({why}: {dof:.0f} residual dof)")
    return out


def _noise_share(
    normalised: FloatArray,
    J: FloatArray,
    J_c: FloatArray,
    robot_covariance: FloatArray,
    rows: dict[str, slice],
    noise: dict[str, NoiseLevel],
) -> dict[str, float]:
    """Each group's residual variance that the session's noise explains, as a fraction of its level.

    The residuals of the weighted problem are ``(I − H)(n + J_c c)``: the robot's error adds
    ``Σ_i [(I − H) J_c Σ_c J_cᵀ (I − H)]_ii`` (expected) to a group's residual sum of squares, on top
    of the noise's ``σ² (n_g − Σ h_ii)``. The noise levels estimated from the residuals (the fit's
    weights) contain both; the share ``(RSS_g − robot_g) / RSS_g`` (floored at 0: a stated accuracy
    that explains all the scatter leaves no noise) is what the noise part of the covariance keeps,
    so the robot's error is not counted twice. Groups with an assumed level keep it whole.
    """
    norms = np.linalg.norm(J, axis=0)
    live = norms > 0
    U, s, _ = np.linalg.svd(J[:, live] / norms[live], full_matrices=False)
    U = U[:, s > s[0] * RCOND_LIMIT]
    M = J_c - U @ (U.T @ J_c)  # (I − H) J_c
    robot_rows = np.einsum("ij,jk,ik->i", M, robot_covariance, M)
    out = {}
    for g, part in rows.items():
        rss = float(np.sum(normalised[part] ** 2))
        keep = noise[g].source == "residuals" and rss > 0
        out[g] = max(0.0, 1.0 - float(robot_rows[part].sum()) / rss) if keep else 1.0
    return out


def fit_chain(
    session: Session,
    robot: Robot,
    initial: CalibrationResult,
    model: str = "scaled_uv",
    *,
    samples: np.ndarray | None = None,
    rounds: int = 2,
    joint_offsets: bool = False,
    robot_accuracy: RobotAccuracy | None = DEFAULT_ROBOT_ACCURACY,
) -> ChainFit:
    """Solve the whole chain with one image model (robust stage, then the final fit without outliers).

    Args:
        session: the recorded data.
        robot: the model giving flange poses.
        initial: the sequential result (starting values).
        model: one of :data:`MODELS`.
        samples: ``(N,)`` bool mask of image samples to use (for cross-validation; default all).
        rounds: robust solves, each re-estimating the groups' noise levels from the previous residuals.
        joint_offsets: also estimate the zero offsets of the joints this session identifies.
        robot_accuracy: the robot's stated accuracy, whose effect on the estimate is added to its
            covariance (module docstring); None leaves it out (cross-validation: estimates only).

    Raises:
        DegenerateDataError: the data do not determine the unknowns (:func:`check_conditioning`).
    """
    if model not in MODELS:
        raise InputError(f"unknown image model {model!r}; choose from {', '.join(MODELS)}")
    data = ChainData.of(session, robot)
    joints: tuple[int, ...] = ()
    if joint_offsets:
        first = fit_chain(session, robot, initial, model, samples=samples, rounds=rounds, robot_accuracy=None)
        ratios = identifiable_joint_offsets(session, robot, first)
        joints = tuple(k for k, name in enumerate(robot.joint_names) if ratios[name] > 0.05)
    layout = ParameterLayout(model, joints)
    x, base = _start(initial, layout, data.spacing_m)
    use = np.ones(len(data.uv_px), dtype=bool) if samples is None else np.asarray(samples, dtype=bool)
    sigma = dict(INITIAL_SIGMA)
    offsets_block = layout.blocks()["joint_offsets"]

    def data_at(x: FloatArray) -> ChainData:
        return ChainData.of(session, robot, layout.offsets(x, robot.nq)) if joints else data

    def solve(x: FloatArray, keep: np.ndarray, loss: str, tol: float = 1e-10):
        def residual(x: FloatArray) -> FloatArray:
            r = chain_residuals(x, layout, data_at(x), base, sigma, keep)
            return np.concatenate([r, x[offsets_block] / OFFSET_PRIOR_SD]) if joints else r

        def jacobian(x: FloatArray) -> FloatArray:
            at = data_at(x)
            J = chain_jacobian(x, layout, at, base, sigma, keep)  # zero in the joint offsets' columns
            if not joints:
                return J
            # Joint offsets move the flange poses: their columns by forward differences (steps of
            # 1e-7 rad, where rounding and curvature both stay below 1e-7 of the derivative).
            r0 = chain_residuals(x, layout, at, base, sigma, keep)
            for column in range(offsets_block.start, offsets_block.stop):
                shifted = x.copy()
                shifted[column] += 1e-7
                J[:, column] = (chain_residuals(shifted, layout, data_at(shifted), base, sigma, keep) - r0) / 1e-7
            prior = np.zeros((len(joints), len(x)))
            prior[:, offsets_block] = np.eye(len(joints)) / OFFSET_PRIOR_SD
            return np.vstack([J, prior])

        return least_squares(
            residual,
            x,
            jac=jacobian,
            method="trf",
            loss=loss,
            f_scale=1.0,
            x_scale="jac",
            xtol=tol,
            ftol=tol,
            gtol=tol,
            max_nfev=200,
        )

    def flagged(x: FloatArray) -> np.ndarray:
        T_ER_Ntip, T_EL_Ptip, T_Ptip_I, _, spacing = layout.unpack(x, base, data.spacing_m)
        residuals = _image_residuals(data_at(x), T_ER_Ntip, T_EL_Ptip @ T_Ptip_I, spacing)
        return np.linalg.norm(residuals, axis=1) / (np.sqrt(3.0) * sigma["image"]) > OUTLIER_THRESHOLD

    # Robust stage: find the gross errors.
    for _ in range(max(rounds, 1)):
        fit = solve(x, use, "soft_l1")
        x = fit.x
        noise = _noise_levels(fit.fun, fit.jac, data.group_rows(int(use.sum())), sigma, robust=True)
        sigma = {g: n.sd_m for g, n in noise.items()}
    outliers = use & flagged(x)
    # Final stage: least squares without them; noise levels from the residuals, dof-corrected.
    for attempt in range(3):  # a sample flagged (or cleared) by the final fit is dropped (or restored)
        keep = use & ~outliers
        for _ in range(NOISE_ITERATIONS):  # weights and noise levels to their common fixed point
            fit = solve(x, keep, "linear")
            x = fit.x
            noise = _noise_levels(fit.fun, fit.jac, data.group_rows(int(keep.sum())), sigma, robust=False)
            change = max(abs(noise[g].sd_m / sigma[g] - 1.0) for g in GROUPS)
            sigma = {g: n.sd_m for g, n in noise.items()}
            if change < 1e-6:
                break
        again = use & flagged(x)
        if np.array_equal(again, outliers) or attempt == 2:
            break
        outliers = again
    fit = solve(x, keep, "linear", tol=1e-15)  # the estimate: to the last digit (the others only weight and flag)
    x = fit.x
    conditioning, noise_covariance = check_conditioning(fit.jac, layout, session, keep)
    covariance, sensitivity, robot_covariance, share = noise_covariance, None, None, {}
    if robot_accuracy is not None:
        J_c = _robot_jacobian(session, robot, layout, x, base, sigma, keep)
        J_c = np.vstack([J_c, np.zeros((len(fit.jac) - len(J_c), J_c.shape[1]))])  # the offsets' prior rows
        # The data come from the physical robot, model + c: at the truth the model's residuals are
        # −J_c c, and least squares moves the estimate by −(JᵀJ)⁻¹Jᵀ(−J_c c) = S c.
        sensitivity = noise_covariance @ (fit.jac.T @ J_c)
        robot_covariance = robot_accuracy.covariance(robot)
        share = _noise_share(fit.fun, fit.jac, J_c, robot_covariance, data.group_rows(int(keep.sum())), noise)
        rows = np.ones(len(fit.fun))
        for g, part in data.group_rows(int(keep.sum())).items():
            rows[part] = share[g]
        # Sandwich: the weights stay the residuals' levels (the estimate does not depend on the
        # stated accuracy); the noise part uses each group's noise alone, the robot's part apart.
        noise_covariance = noise_covariance @ (fit.jac.T * rows) @ fit.jac @ noise_covariance
        covariance = noise_covariance + sensitivity @ robot_covariance @ sensitivity.T
    T_ER_Ntip, T_EL_Ptip, T_Ptip_I, rtips, spacing = layout.unpack(x, base, data.spacing_m)
    residuals = _image_residuals(data_at(x), T_ER_Ntip, T_EL_Ptip @ T_Ptip_I, spacing)
    sound = None if model in ("rigid",) else float(SCANNER_SOUND_SPEED * spacing[1] / data.spacing_m[1])
    offsets = {robot.joint_names[k]: float(v) for k, v in zip(joints, x[offsets_block], strict=True)}
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
        noise,
        conditioning,
        noise_covariance,
        sensitivity,
        robot_covariance,
        robot_accuracy,
        share,
    )


def check_conditioning(
    J: FloatArray, layout: ParameterLayout, session: Session, used: np.ndarray
) -> tuple[Conditioning, FloatArray]:
    """Refuse a fit whose data do not determine its unknowns; else return its covariance.

    ``J`` is the Jacobian of the normalised residuals at the solution. Two refusals
    (:class:`~brachycal.errors.DegenerateDataError`, naming the unknowns and the session file):

    - **undetermined**: the reciprocal condition number of ``J`` with unit-norm columns is below
      :data:`RCOND_LIMIT` (a combination of unknowns the data do not see at all: e.g. every image
      sample at one robot pose and pixel, or too few samples);
    - **linearisation invalid**: a fitted rotation's largest SD exceeds :data:`ROTATION_SD_LIMIT`
      (e.g. samples spread over a pixel or two: the image rotation is then known only to tens of
      degrees and no linearised interval or predicted error would hold).

    Returns:
        The conditioning figures and the covariance ``(JᵀJ)⁻¹`` ``(P, P)``.
    """
    norms = np.linalg.norm(J, axis=0)
    blocks = layout.blocks()
    if np.any(norms == 0):
        column = int(np.argmin(norms))
        _refuse(blocks, [column], "does not enter any residual", session, used)
    _, s, Vt = np.linalg.svd(J / norms, full_matrices=False)
    rcond = float(s[-1] / s[0])
    if rcond < RCOND_LIMIT:
        weakest = np.argsort(-np.abs(Vt[-1]))
        involved = [int(k) for k in weakest if abs(Vt[-1][k]) > 0.2] or [int(weakest[0])]
        _refuse(
            blocks,
            involved,
            f"are not determined by the data (reciprocal condition {rcond:.1e}, limit {RCOND_LIMIT:.0e})",
            session,
            used,
        )
    # (JᵀJ)⁻¹ in the scaled coordinates, scaled back: exact inverse, no truncation.
    covariance = (Vt.T / s**2) @ Vt / np.outer(norms, norms)
    rotation_sd = {
        name: float(np.sqrt(max(np.linalg.eigvalsh(covariance[blocks[name], blocks[name]]).max(), 0.0)))
        for name in ROTATIONS
    }
    worst = max(rotation_sd, key=lambda name: rotation_sd[name])
    if rotation_sd[worst] > ROTATION_SD_LIMIT:
        _refuse(
            blocks,
            [blocks[worst].start],
            f"is determined only to {np.degrees(rotation_sd[worst]):.1f}° SD "
            f"(limit {np.degrees(ROTATION_SD_LIMIT):.1f}°, where linearised intervals stop holding)",
            session,
            used,
        )
    return Conditioning(rcond, rotation_sd), covariance


def _refuse(blocks: dict[str, slice], columns: list[int], problem: str, session: Session, used: np.ndarray):
    names = []
    for column in columns:
        name = next(n for n, s in blocks.items() if s.start <= column < s.stop)
        if name not in names:
            names.append(name)
    labels = [BLOCK_LABELS[n][0] for n in names]
    files = sorted({BLOCK_LABELS[n][1] for n in names})
    what = labels[0] if len(labels) == 1 else ", ".join(labels[:-1]) + " and " + labels[-1]
    advice = ""
    if "samples.csv" in files:
        q = session.samples_q[used]
        poses = len(np.unique(np.round(q, 6), axis=0))
        span = np.ptp(session.uv_px[used], axis=0) if used.any() else np.zeros(2)
        advice = (
            f"; the {int(used.sum())} image samples come from {poses} distinct robot pose(s) and span "
            f"{span[0]:.0f} x {span[1]:.0f} px: record the needle at several probe poses spread over the image"
        )
    raise DegenerateDataError(f"whole chain: {what} {problem}{advice}", file=files[0] if len(files) == 1 else None)


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
    without them. Samples in ``exclude`` (flagged outliers) are fitted robustly but not scored.

    Raises:
        DegenerateDataError: a fold's training samples do not determine the chain.
    """
    n = len(session.uv_px)
    order = np.random.default_rng(seed).permutation(n)
    errors = np.empty(n)
    data = ChainData.of(session, robot)
    for fold in range(folds):
        held = np.zeros(n, dtype=bool)
        held[order[fold::folds]] = True
        try:
            fit = fit_chain(session, robot, initial, model, samples=~held, rounds=1, robot_accuracy=None)
        except DegenerateDataError as exc:
            left_out = ", ".join(session.sample_ids[i] for i in np.flatnonzero(held)[:3])
            raise DegenerateDataError(f"{model} cross-validation without sample(s) {left_out}: {exc.problem}") from None
        residuals = _image_residuals(data, fit.T_ER_Ntip, fit.T_EL_Ptip @ fit.image.T_Ptip_I, fit.image.spacing_m)
        errors[held] = np.linalg.norm(residuals[held], axis=1)
    keep = np.ones(n, dtype=bool) if exclude is None else ~np.asarray(exclude, dtype=bool)
    return ErrorStats(errors[keep])


@dataclass(frozen=True)
class ModelChoice:
    """The chosen image model and the evidence: cross-validated errors per model (outliers not scored).

    ``undetermined`` lists the models the data cannot determine (model → the reason), left out.
    """

    model: str
    cv: dict[str, ErrorStats]
    rule: str
    scored_samples: int
    undetermined: dict[str, str] = field(default_factory=dict)

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

    Samples that the most flexible determined model flags as gross outliers are left out of the
    scores (they would dominate every model's error alike). A model the data cannot determine
    (:func:`check_conditioning`) is left out of the choice, with its reason.

    Raises:
        DegenerateDataError: no model is determined by the data.
    """
    undetermined: dict[str, str] = {}
    flagged = None
    for m in sorted(models, key=lambda m: -COMPLEXITY[m]):
        try:
            flagged = fit_chain(session, robot, initial, m, robot_accuracy=None).outliers
            break
        except DegenerateDataError as exc:
            undetermined[m] = exc.problem
    if flagged is None:
        raise DegenerateDataError(next(iter(undetermined.values())))
    cv = {}
    for m in models:
        if m in undetermined:
            continue
        try:
            cv[m] = cross_validate(session, robot, initial, m, folds, exclude=flagged)
        except DegenerateDataError as exc:
            undetermined[m] = exc.problem
    if not cv:
        raise DegenerateDataError(next(iter(undetermined.values())))
    rule = "simplest model within one standard error of the lowest cross-validated RMSE (outliers not scored)"
    evidence = ModelChoice("", cv, rule, int((~flagged).sum())).evidence()
    best = min(evidence, key=lambda m: evidence[m]["cv_rmse_mm"])
    limit = evidence[best]["cv_rmse_mm"] + evidence[best]["se_mm"]
    eligible = [m for m in cv if evidence[m]["cv_rmse_mm"] <= limit]
    chosen = min(eligible, key=lambda m: (COMPLEXITY[m], evidence[m]["cv_rmse_mm"]))
    return ModelChoice(chosen, cv, rule, int((~flagged).sum()), undetermined)


def identifiable_joint_offsets(
    session: Session, robot: Robot, fit: ChainFit, tolerance: float = 0.05
) -> dict[str, float]:
    """How much of each joint's zero-offset effect the chain parameters cannot absorb.

    For joint k, the residuals' derivative with respect to a common offset of that joint in every
    recorded configuration is compared with the span of the chain parameters' Jacobian; the
    returned number is the part left outside that span (0: fully confounded, 1: independent).
    A joint offset is identifiable from this session when that part exceeds ``tolerance``.
    """
    layout = ParameterLayout(fit.model)
    use = np.ones(len(session.uv_px), dtype=bool)
    data = ChainData.of(session, robot)
    sigma = fit.sigma_m

    def residuals(data_k: ChainData) -> FloatArray:
        return chain_residuals(fit.x[: layout.size], layout, data_k, fit.base, sigma, use)

    r0 = residuals(data)
    J = chain_jacobian(fit.x[: layout.size], layout, data, fit.base, sigma, use)
    Q, _ = np.linalg.qr(J)
    out = {}
    step = 1e-6
    for k, name in enumerate(robot.joint_names):
        shifted = _shift_joint(session, k, step)
        column = (residuals(ChainData.of(shifted, robot)) - r0) / step
        norm_column = np.linalg.norm(column)
        out[name] = 0.0 if norm_column == 0 else float(np.linalg.norm(column - Q @ (Q.T @ column)) / norm_column)
    return out


def _shift_joint(session: Session, k: int, delta: float) -> Session:
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
    layout = ParameterLayout(fit.model)
    data = ChainData.of(session, robot)
    use = np.ones(len(session.uv_px), dtype=bool)
    J = chain_jacobian(fit.x[: layout.size], layout, data, fit.base, fit.sigma_m, use)
    n_images = 3 * len(session.uv_px)
    fixed = J[:-n_images]
    return fixed.T @ fixed, J[-n_images:].reshape(len(session.uv_px), 3, layout.size)
