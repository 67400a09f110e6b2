"""One solved chain problem: :class:`ChainFit`, and its robot Jacobian (:func:`robot_jacobian`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from brachycal.calibration.chain.conditioning import Conditioning
from brachycal.calibration.chain.layout import ParameterLayout
from brachycal.calibration.chain.noise import NoiseLevel
from brachycal.calibration.chain.robot_terms import robot_jacobian_at
from brachycal.calibration.result import Calibration, ImageCalibration
from brachycal.calibration.robot_accuracy import RobotAccuracy
from brachycal.data.session import Session
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray


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
        robot_mean / robot_posterior: ``(6 nq,)`` and ``(6 nq, 6 nq)``: ``c`` given the fit's residuals
            (:func:`~brachycal.calibration.chain.noise.robot_posterior`), what the predicted landing
            error uses; None where ``robot_covariance`` is already a posterior (an identified robot)
            or without a stated accuracy.
        robot_accuracy: the stated accuracy (None: the robot term was not computed).
        noise_share: per group, the fraction of its residual variance left to the session's noise
            once the stated robot accuracy's expected part is taken out
            (:func:`~brachycal.calibration.chain.noise_share`).
        image_axes_noise: the image samples' noise level along each image axis (lateral, depth,
            normal; :func:`~brachycal.calibration.chain.image_axis_levels`): the annotation noise
            lies in the plane, which the per-coordinate ``noise["image"]`` pools with the normal.
        robust_x: ``(P,)`` the robust stage's estimate (soft-L1): where a refit on nearly the same
            samples starts its own robust stage (cross-validation's folds; None if not kept).
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
    robot_mean: FloatArray | None = field(default=None, repr=False)
    robot_posterior: FloatArray | None = field(default=None, repr=False)
    noise_share: dict[str, float] = field(default_factory=dict)
    robust_x: FloatArray | None = field(default=None, repr=False)
    image_axes_noise: dict[str, NoiseLevel] = field(default_factory=dict)

    def calibration(self) -> Calibration:
        """The fit as a :class:`~brachycal.calibration.result.Calibration` (method ``image.method``,
        its joint offsets as robot corrections; no provenance: the caller knows the session)."""
        return Calibration(self.T_ER_Ntip, self.T_EL_Ptip, self.image, joint_offsets_rad=self.joint_offsets_rad)

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

    def layout(self, joint_names: tuple[str, ...]) -> ParameterLayout:
        """The layout of ``x``, with the estimated joint offsets' indices in ``joint_names`` (the robot's order)."""
        return ParameterLayout(self.model, tuple(joint_names.index(n) for n in self.joint_offsets_rad))

    def block(self, name: str) -> slice:
        """The slice of parameter ``name`` (see :data:`~brachycal.calibration.chain.layout.BLOCK_LABELS`)
        in ``x`` and ``covariance``."""
        s = ParameterLayout(self.model).blocks()[name]
        return slice(s.start, len(self.x)) if name == "joint_offsets" else s

    def noise_text(self) -> str:
        """The noise levels in one line, each with its source."""
        names = {"touch": "touches", "axes": "axes moves", "image": "images"}
        return "; ".join(f"{names[g]} {n.note}" for g, n in self.noise.items()) or ", ".join(
            f"{names[g]} {v * 1e3:.3f} mm" for g, v in self.sigma_m.items()
        )


def robot_jacobian(session: Session, robot: Robot, fit: ChainFit) -> FloatArray:
    """``(M, 6 nq)`` ``J_c``: the fit's normalised residuals (its final problem: its noise levels,
    its samples) differentiated with respect to every joint's origin motion ``(v, ω)`` (metres,
    radians; joint-major in ``robot.joint_names`` order; see
    :func:`~brachycal.calibration.chain.robot_terms.joint_twists`)."""
    layout = fit.layout(robot.joint_names)
    return robot_jacobian_at(session, robot, layout, fit.x, fit.base, fit.sigma_m, ~fit.outliers)
