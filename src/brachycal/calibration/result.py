"""What a calibration gives, below the methods that compute it: the image's calibration
(:class:`ImageCalibration`, a rigid ``T_Ptip_I`` with its pixel spacing, and its
:class:`PredictedUncertainty`) and the robot model carrying the calibrated tool and image frames
(:func:`calibrated_robot`). Metres and radians; ``T_a_b`` maps frame b into frame a.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from brachycal.imaging.pixels import image_points
from brachycal.model.names import NEEDLE_TIP, PROBE_TIP, US_IMAGE
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray, transform_points

__all__ = [
    "Calibration",
    "ImageCalibration",
    "PredictedUncertainty",
    "Provenance",
    "best_method",
    "calibrated_robot",
    "locate",
]


@dataclass(frozen=True)
class PredictedUncertainty:
    """Predicted uncertainty of an image calibration from its residual and its design (SI units).

    Attributes:
        noise_sd_m: noise per coordinate estimated from the fit's residual (``σ̂``), metres.
        rotation_sd_deg: RMS angle of the rotation's error, degrees.
        origin_sd_m: 3D SD of the image origin (pixel (0, 0)) in the probe frame, metres.
        spacing_sd_m: ``(2,)`` SD of the fitted spacings ``(s_u, s_v)``, metres (0 for rigid methods).
        samples_sd_m: RMS over the samples of the predicted 3D SD of their mapped points, metres.
        reach_sd_m: largest predicted 3D SD at
            :data:`~brachycal.calibration.sequential.image_to_probe.REACH_M` from the samples' centroid, metres.
    """

    noise_sd_m: float
    rotation_sd_deg: float
    origin_sd_m: float
    spacing_sd_m: FloatArray
    samples_sd_m: float
    reach_sd_m: float

    def as_dict(self) -> dict[str, object]:
        """JSON-ready figures in millimetres and degrees."""
        return {
            "noise_sd_mm": self.noise_sd_m * 1e3,
            "rotation_sd_deg": self.rotation_sd_deg,
            "origin_sd_mm": self.origin_sd_m * 1e3,
            "spacing_sd_mm": (np.asarray(self.spacing_sd_m) * 1e3).tolist(),
            "samples_sd_mm": self.samples_sd_m * 1e3,
            "reach_sd_mm": self.reach_sd_m * 1e3,
        }


@dataclass(frozen=True, repr=False)
class ImageCalibration:
    """``T_Ptip_I (4, 4)`` (rigid) and the pixel spacing ``(s_u, s_v)`` in metres it goes with.

    ``uncertainty`` is set by :func:`~brachycal.calibration.sequential.image_to_probe.fit` (``None`` for
    calibrations read back from a file).
    """

    method: str
    T_Ptip_I: FloatArray
    spacing_m: FloatArray
    uncertainty: PredictedUncertainty | None = None

    def __repr__(self) -> str:
        return f"ImageCalibration {self.method!r}: T_Ptip_I, {image_summary(self)}"

    def image_points(self, uv_px: ArrayLike) -> FloatArray:
        """``p_I (N, 3)``: pixels ``(N, 2)`` as points of the image frame, metres."""
        return image_points(uv_px, self.spacing_m)

    def probe_points(self, uv_px: ArrayLike) -> FloatArray:
        """``p_Ptip (N, 3)`` of pixels ``(N, 2)``."""
        return transform_points(self.T_Ptip_I, self.image_points(uv_px))


def calibrated_robot(robot: Robot, T_ER_Ntip: ArrayLike, T_EL_Ptip: ArrayLike, image: ImageCalibration) -> Robot:
    """``robot`` with the calibrated tool and image frames: the needle tip ``T_ER_Ntip (4, 4)`` on the
    needle flange, the probe tip ``T_EL_Ptip (4, 4)`` on the probe flange and the image ``image.T_Ptip_I``
    on the probe tip (metres)."""
    out = robot.with_tool_transform(NEEDLE_TIP, T_ER_Ntip).with_tool_transform(PROBE_TIP, T_EL_Ptip)
    return out.with_tool_transform(US_IMAGE, image.T_Ptip_I)


def point_mm(T: ArrayLike) -> str:
    """The translation of a ``(4, 4)`` transform (metres) as ``(x, y, z) mm`` for a summary."""
    x, y, z = np.asarray(T, dtype=float)[:3, 3] * 1e3
    return f"({x:.2f}, {y:.2f}, {z:.2f}) mm"


def image_summary(image: ImageCalibration) -> str:
    """One line: the image frame in the probe tip (origin, mm) and the spacing (mm/px)."""
    s_u, s_v = np.asarray(image.spacing_m, dtype=float) * 1e3
    return f"image origin (pixel 0, 0) at {point_mm(image.T_Ptip_I)} in probe_tip, spacing {s_u:.4f} x {s_v:.4f} mm/px"


def _frozen(mapping: Mapping | None) -> Mapping:
    """A read-only copy (a frozen value holds no dict its maker could change later)."""
    return MappingProxyType(dict(mapping or {}))


def _matrix(value: ArrayLike) -> FloatArray:
    """A read-only float copy (a frozen value holds no array its maker could change later)."""
    out = np.array(value, dtype=float)
    out.flags.writeable = False
    return out


@dataclass(frozen=True)
class Provenance:
    """Where a :class:`Calibration` came from.

    Attributes:
        source: the result file it was read from ("" for one computed in this process).
        sha256: SHA-256 of that file's bytes ("").
        inputs: the session's input files it was calibrated from → their SHA-256.
    """

    source: str = ""
    sha256: str = ""
    inputs: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "inputs", _frozen(self.inputs))


@dataclass(frozen=True, eq=False, repr=False)
class Calibration:
    """One calibration of the rig, what every consumer takes (locate, plan, export, verify, view, targeting).

    Attributes:
        T_ER_Ntip: ``(4, 4)`` the needle tip in the needle (right) flange, metres.
        T_EL_Ptip: ``(4, 4)`` the probe tip in the probe (left) flange, metres.
        image: the image calibration: ``T_Ptip_I (4, 4)`` (image frame in the probe tip, metres)
            and the pixel spacing ``(s_u, s_v)`` in metres; ``image.method`` names the method
            (``"kabsch"``, ``"chain"``, ...).
        joint_offsets_rad: joint → zero offset, radians (robot corrections; empty: none).
        joint_origins: joint → ``(URDF origin (4, 4), corrected origin (4, 4))``, metres: the robot
            corrections as the result file holds them (empty: none).
        image_size_px: ``(width, height)`` of the calibrated images, pixels (None: not known).
        provenance: the result file and session inputs it came from.

    Arrays are read-only copies. Compare two with :meth:`max_difference` (no ``==``: arrays).
    """

    T_ER_Ntip: FloatArray
    T_EL_Ptip: FloatArray
    image: ImageCalibration
    joint_offsets_rad: Mapping[str, float] = field(default_factory=dict)
    joint_origins: Mapping[str, tuple[FloatArray, FloatArray]] = field(default_factory=dict)
    image_size_px: tuple[int, int] | None = None
    provenance: Provenance = field(default_factory=Provenance)

    def __post_init__(self) -> None:
        object.__setattr__(self, "T_ER_Ntip", _matrix(self.T_ER_Ntip))
        object.__setattr__(self, "T_EL_Ptip", _matrix(self.T_EL_Ptip))
        object.__setattr__(self, "joint_offsets_rad", _frozen({k: float(v) for k, v in self.joint_offsets_rad.items()}))
        origins = {k: (_matrix(a), _matrix(b)) for k, (a, b) in self.joint_origins.items()}
        object.__setattr__(self, "joint_origins", _frozen(origins))

    def __repr__(self) -> str:
        """A few lines: the method, each transform's origin in its parent frame (mm), the robot
        corrections and where it came from (the arrays themselves: the attributes)."""
        size = "" if self.image_size_px is None else f", images {self.image_size_px[0]} x {self.image_size_px[1]} px"
        corrected = len(set(self.joint_offsets_rad) | set(self.joint_origins))
        source = self.provenance.source or "computed in this process"
        return "\n".join(
            [
                f"Calibration {self.method!r} (transforms T_parent_child in metres; shown in mm){size}",
                f"  T_ER_Ntip  needle_tip at {point_mm(self.T_ER_Ntip)} in the needle flange",
                f"  T_EL_Ptip  probe_tip at {point_mm(self.T_EL_Ptip)} in the probe flange",
                f"  T_Ptip_I   {image_summary(self.image)}",
                f"  robot corrections: {corrected} joint(s); source: {source}",
            ]
        )

    @property
    def method(self) -> str:
        """The image calibration's method (``image.method``)."""
        return self.image.method

    @property
    def T_Ptip_I(self) -> FloatArray:
        """``(4, 4)`` the image frame in the probe tip, metres (``image.T_Ptip_I``)."""
        return self.image.T_Ptip_I

    @property
    def spacing_m(self) -> FloatArray:
        """``(2,)`` pixel spacing ``(s_u, s_v)``, metres (``image.spacing_m``)."""
        return self.image.spacing_m

    def robot(self, robot: Robot) -> Robot:
        """``robot`` with this calibration's tool and image frames (:func:`calibrated_robot`); robot
        corrections are not applied here (the result file decides whether a robot carries them)."""
        return calibrated_robot(robot, self.T_ER_Ntip, self.T_EL_Ptip, self.image)

    def max_difference(self, other: Calibration) -> float:
        """Largest absolute difference of the transforms, spacings and robot corrections (metres,
        radians, unitless rotation entries); ``inf`` when the methods, joints or image sizes differ."""
        if (
            self.method != other.method
            or set(self.joint_offsets_rad) != set(other.joint_offsets_rad)
            or set(self.joint_origins) != set(other.joint_origins)
            or self.image_size_px != other.image_size_px
        ):
            return float("inf")
        pairs = [
            (self.T_ER_Ntip, other.T_ER_Ntip),
            (self.T_EL_Ptip, other.T_EL_Ptip),
            (self.image.T_Ptip_I, other.image.T_Ptip_I),
            (self.image.spacing_m, other.image.spacing_m),
        ]
        pairs += [(np.array([v]), np.array([other.joint_offsets_rad[k]])) for k, v in self.joint_offsets_rad.items()]
        for k, (a, b) in self.joint_origins.items():
            pairs += [(a, other.joint_origins[k][0]), (b, other.joint_origins[k][1])]
        return max(float(np.max(np.abs(np.asarray(a) - np.asarray(b)))) for a, b in pairs)


def locate(robot: Robot, q: ArrayLike, uv_px: ArrayLike, calibration: Calibration) -> FloatArray:
    """Targeting: image pixels ``(N, 2)`` → ``p_R (N, 3)`` in the robot's base frame at configuration(s)
    ``q`` (``T_R_EL`` is the rig's probe flange): ``p_R = T_R_EL(q) @ T_EL_Ptip @ T_Ptip_I @ p_I``,
    ``p_I = (u·s_u, v·s_v, 0)``, metres."""
    T_R_EL = robot.fk(robot.rig.probe_flange, np.asarray(q, dtype=float))
    T_R_I = np.asarray(T_R_EL) @ calibration.T_EL_Ptip @ calibration.image.T_Ptip_I
    return transform_points(T_R_I, calibration.image.image_points(uv_px))


#: Leave-one-out RMSEs closer than this (relative) are a tie in :func:`best_method`: far above
#: rounding (two methods that solve the same least squares agree to ~1e-14), far below any
#: difference between methods that matters (a nanometre in a millimetre).
TIE_RELATIVE = 1e-9


def best_method(methods: Sequence[str], rmse_mm: Mapping[str, object]) -> str:
    """The image calibration to use when none is asked for, among ``methods`` (in preference order).

    The whole chain's if there is one (``chain+robot``, then ``chain``); otherwise the lowest
    leave-one-out RMSE (``rmse_mm``, millimetres; a method without one, or a non-finite one, comes
    last); RMSEs within :data:`TIE_RELATIVE` of each other are ties, broken by the order of ``methods``.
    """
    for chain in ("chain+robot", "chain"):
        if chain in methods:
            return chain

    def rmse(method: str) -> float:
        value = rmse_mm.get(method)
        return float(value) if isinstance(value, int | float) and np.isfinite(value) else np.inf

    best = min(rmse(m) for m in methods)
    # The first in the given order within the tie tolerance of the best (all inf: the first).
    return next(m for m in methods if rmse(m) <= best * (1 + TIE_RELATIVE))


def best_reason(method: str, rmse_mm: object = None) -> str:
    """Why :func:`best_method` chose ``method``, in words (``rmse_mm``: its leave-one-out RMSE, mm)."""
    if method == "chain+robot":
        return "the whole chain with the robot's geometry, solved over all the data"
    if method == "chain":
        return "the whole chain, solved over all the data"
    return "lowest leave-one-out RMSE" + (f", {rmse_mm:.3f} mm" if isinstance(rmse_mm, int | float) else "")


def calibration_args(function: str, first: Calibration | ArrayLike, rest: tuple[Any, ...]) -> tuple[Calibration, tuple]:
    """``(calibration, the remaining positional arguments)`` of a function that takes one
    :class:`~brachycal.calibration.result.Calibration`, or the loose ``T_ER_Ntip, T_EL_Ptip, image``
    it took before (accepted for one release, with a :class:`DeprecationWarning`)."""
    if isinstance(first, Calibration):
        return first, rest
    if len(rest) < 2 or not isinstance(rest[1], ImageCalibration):
        raise TypeError(f"{function}() takes a Calibration")
    warnings.warn(
        f"{function}(T_ER_Ntip, T_EL_Ptip, image, ...) is deprecated: pass one Calibration",
        DeprecationWarning,
        stacklevel=3,
    )
    return Calibration(np.asarray(first, dtype=float), rest[0], rest[1]), rest[2:]
