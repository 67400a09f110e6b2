"""N-wire calibration of PLUS files, and its result file ``brachycal-nwire/1`` (JSON).

:func:`nwire_from_files` reads a PLUS device-set configuration and a segmented-frames file
(:mod:`brachycal.data.plus_files`), fits both image models of :mod:`brachycal.calibration.nwire`
on the calibration frames and validates them on the validation frames; :func:`write_nwire`
writes the result and :func:`read_nwire` reads it back.

The file holds ``T_Probe_Image`` (rigid, metres) with its pixel spacing (``spacing_mm``), PLUS's
affine Image→Probe in millimetres (``affine_mm``, as PLUS writes it) with the pixel sizes it implies,
the angle between the two models' rotations, the point counts, per model the 3D reprojection
errors (all points and the best 95 %, as PLUS reports them) on the validation and calibration
frames and the per-wire 2D errors in pixels, and the SHA-256 of both inputs.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.nwire import (
    NWireCalibration,
    best_fraction,
    calibrate_nwire,
    reprojection_errors,
    rotation_difference_deg,
    wire_errors_2d,
    wire_point_pairs,
)
from brachycal.data.json_files import read_format_json
from brachycal.data.plus_files import read_plus_config, read_segmented_frames
from brachycal.errors import InputError
from brachycal.files import sha256_file, write_json
from brachycal.se3 import FloatArray
from brachycal.validate import check_spacing_mm, check_transform

FORMAT = "brachycal-nwire/1"
#: The image models fitted and validated: PLUS's affine matrix, and a rotation with two spacings.
NWIRE_MODELS = ("affine", "rigid")
#: Spacing the rigid + spacings fit starts from when the configuration states none, metres per
#: pixel (0.1 mm/px, a typical ultrasound spacing; only the fit's starting point).
FALLBACK_SPACING_M = 1e-4


@dataclass(frozen=True)
class WireErrors:
    """Signed 2D errors of one wire (segmented − projected) over the validation frames, pixels."""

    mean_px: FloatArray
    sd_px: FloatArray
    n: int


@dataclass(frozen=True)
class ModelValidation:
    """How one image model reprojects: 3D errors (metres) on both frame sets, 2D errors per wire."""

    validation_3d: ErrorStats
    calibration_3d: ErrorStats
    wires_2d: dict[str, WireErrors]

    @property
    def validation_best95(self) -> ErrorStats:
        """The best 95 % of the validation errors: what PLUS reports as its validation error."""
        return best_fraction(self.validation_3d)


@dataclass(frozen=True)
class NWireRun:
    """An N-wire calibration of PLUS files and its validation.

    Attributes:
        calibration: the fitted models (rigid ``T_probe_image`` with spacings, and PLUS's affine).
        models: model (:data:`NWIRE_MODELS`) → its validation.
        calibration_points, validation_points: middle-wire points used to fit and to validate.
        frames_used, frames_total: calibration frames whose segmentation is usable, and all of them.
        validation_frames: validation frames in the file.
        start_spacing_m: the spacing the fit started from (the configuration's, metres per pixel).
        inputs: file name → SHA-256 of the configuration and the frames file.
    """

    calibration: NWireCalibration
    models: dict[str, ModelValidation]
    calibration_points: int
    validation_points: int
    frames_used: int
    frames_total: int
    validation_frames: int
    start_spacing_m: float
    inputs: dict[str, str]

    @property
    def affine_spacing_m(self) -> FloatArray:
        """``(2,)`` pixel sizes the affine model implies (lengths of its u and v columns), metres."""
        return np.linalg.norm(self.calibration.affine[:3, :2], axis=0)

    @property
    def rigid_vs_affine_deg(self) -> float:
        """Angle between the rigid and the affine models' rotations, degrees."""
        return rotation_difference_deg(self.calibration.T_probe_image, self.calibration.affine)

    def to_json(self) -> dict[str, object]:
        """The ``brachycal-nwire/1`` payload (metres; ``*_mm`` and ``*_px`` where the key says)."""
        c = self.calibration
        affine_mm = c.affine.copy()
        affine_mm[:3, :] *= 1e3
        return {
            "format": FORMAT,
            "T_Probe_Image": c.T_probe_image.tolist(),
            "spacing_mm": (c.spacing_m * 1e3).tolist(),
            "affine_mm": affine_mm.tolist(),
            "affine_spacing_mm": (self.affine_spacing_m * 1e3).tolist(),
            "rigid_vs_affine_deg": self.rigid_vs_affine_deg,
            "calibration_points": self.calibration_points,
            "rigid_inliers": int(c.inliers.sum()),
            "validation_points": self.validation_points,
            "errors": {
                model: {
                    "validation_3d": _stats_json(v.validation_3d),
                    "calibration_3d": _stats_json(v.calibration_3d),
                    "wires_2d_px": {
                        name: {"mean": e.mean_px.tolist(), "sd": e.sd_px.tolist(), "n": e.n}
                        for name, e in v.wires_2d.items()
                    },
                }
                for model, v in self.models.items()
            },
            "inputs": self.inputs,
        }


def _stats_json(stats: ErrorStats) -> dict[str, float | int]:
    """Mean, SD and max of 3D errors, and of the best 95 % (PLUS's figures), millimetres."""
    best = best_fraction(stats)
    return {
        "n": stats.n,
        "mean_mm": stats.mae_mm,
        "sd_mm": stats.sd_mm,
        "max_mm": stats.max_mm,
        "best95_mean_mm": best.mae_mm,
        "best95_sd_mm": best.sd_mm,
    }


def nwire_from_files(config_path: str | os.PathLike[str], frames_path: str | os.PathLike[str]) -> NWireRun:
    """Calibrate Image → Probe from a PLUS configuration and segmented frames, and validate it.

    Args:
        config_path: PLUS device-set configuration XML (phantom wires, Phantom→Reference).
        frames_path: PLUS segmented-frames XML (calibration and validation frames).

    Raises:
        InputError: a file is unreadable or malformed, or has no usable validation frame.
        DegenerateDataError: the middle-wire points cannot determine the fit.
    """
    config = read_plus_config(config_path)
    calibration_frames, validation_frames = read_segmented_frames(frames_path)
    uv, p_probe, _ = wire_point_pairs(config, calibration_frames)
    start_spacing = config.approximate_spacing_m or FALLBACK_SPACING_M
    calibration = calibrate_nwire(uv, p_probe, start_spacing)
    if not any(f.ok for f in validation_frames):
        raise InputError("no usable validation frames", file=frames_path)
    uv_v, p_v, _ = wire_point_pairs(config, validation_frames)
    models = {}
    for model in NWIRE_MODELS:
        wires = wire_errors_2d(calibration, config, validation_frames, model)
        models[model] = ModelValidation(
            validation_3d=reprojection_errors(calibration, uv_v, p_v, model),
            calibration_3d=reprojection_errors(calibration, uv, p_probe, model),
            wires_2d={name: WireErrors(e.mean(axis=0), e.std(axis=0), len(e)) for name, e in wires.items()},
        )
    return NWireRun(
        calibration=calibration,
        models=models,
        calibration_points=len(uv),
        validation_points=len(uv_v),
        frames_used=sum(f.ok for f in calibration_frames),
        frames_total=len(calibration_frames),
        validation_frames=len(validation_frames),
        start_spacing_m=start_spacing,
        inputs={Path(p).name: sha256_file(p) for p in (config_path, frames_path)},
    )


def write_nwire(run: NWireRun, path: str | os.PathLike[str], *, force: bool = False) -> Path:
    """Write ``run`` as ``brachycal-nwire/1`` JSON, all or nothing (never NaN).

    Raises:
        OutputError: the file exists (without ``force``), cannot be written, or holds a NaN.
    """
    return write_json(path, run.to_json(), force=force)


@dataclass(frozen=True)
class StoredNWire:
    """What a ``brachycal-nwire/1`` file holds.

    Attributes:
        T_probe_image: ``(4, 4)`` rigid Image → Probe, metres.
        spacing_m: ``(2,)`` its pixel spacing, metres per pixel.
        affine: ``(4, 4)`` PLUS's affine Image → Probe, metres (pixels in, metres out).
        raw: the whole payload (errors, counts, input hashes).
    """

    T_probe_image: FloatArray
    spacing_m: FloatArray
    affine: FloatArray
    raw: dict


def read_nwire(path: str | os.PathLike[str]) -> StoredNWire:
    """Read a ``brachycal-nwire/1`` file back.

    Raises:
        InputError: not readable JSON, another format, a ``T_Probe_Image`` that is not rigid, a
            spacing that is not plausible, or an affine matrix that is not 4×4 finite numbers
            (naming the file and the key).
    """
    path = Path(path)
    raw = read_format_json(path, FORMAT)

    def matrix(key: str) -> FloatArray:
        try:
            M = np.array(raw.get(key), dtype=float)
        except (TypeError, ValueError):
            M = np.empty(0)
        if M.shape != (4, 4) or not np.all(np.isfinite(M)):
            raise InputError("must be a 4x4 matrix of finite numbers", file=path, column=key)
        return M

    try:
        T = check_transform(matrix("T_Probe_Image"), "matrix")
    except InputError as exc:  # restated with the file and the key
        raise InputError(exc.problem, file=path, column="T_Probe_Image") from None
    spacing_mm = raw.get("spacing_mm")
    if spacing_mm is None:
        raise InputError("missing: expected the pixel spacing (s_u, s_v) in mm", file=path, column="spacing_mm")
    spacing_m = check_spacing_mm(spacing_mm, "pixel spacing", file=path, column="spacing_mm") * 1e-3
    affine = matrix("affine_mm")
    affine[:3, :] *= 1e-3
    return StoredNWire(T, spacing_m, affine, raw)
