"""What a calibration gives, below the methods that compute it: the image's calibration
(:class:`ImageCalibration`, a rigid ``T_Ptip_I`` with its pixel spacing, and its
:class:`PredictedUncertainty`) and the robot model carrying the calibrated tool and image frames
(:func:`calibrated_robot`). Metres and radians; ``T_a_b`` maps frame b into frame a.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from brachycal.imaging.pixels import image_points
from brachycal.model.names import NEEDLE_TIP, PROBE_TIP, US_IMAGE
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray, transform_points

__all__ = ["ImageCalibration", "PredictedUncertainty", "calibrated_robot"]


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


@dataclass(frozen=True)
class ImageCalibration:
    """``T_Ptip_I (4, 4)`` (rigid) and the pixel spacing ``(s_u, s_v)`` in metres it goes with.

    ``uncertainty`` is set by :func:`~brachycal.calibration.sequential.image_to_probe.fit` (``None`` for
    calibrations read back from a file).
    """

    method: str
    T_Ptip_I: FloatArray
    spacing_m: FloatArray
    uncertainty: PredictedUncertainty | None = None

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
