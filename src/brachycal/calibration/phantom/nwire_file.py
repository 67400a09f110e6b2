"""N-wire calibration of PLUS files, and its result file ``brachycal-nwire/1`` (JSON).

:func:`calibrate_nwire_files` reads a PLUS device-set configuration and a segmented-frames file
(:mod:`brachycal.data.formats.plus_files`), fits the image models of :mod:`brachycal.calibration.phantom.nwire`
(PLUS's linear ``affine`` fit and brachycal's ``rigid`` rotation + u/v spacings) and PLUS fCal's four
refinements (:mod:`brachycal.calibration.phantom.nwire_refine`) on the calibration frames, validates every
model on the validation frames as PLUS reports it, and chooses one (the lowest best-95 % validation
mean, or the caller's); :func:`write_nwire` writes the result and :func:`read_nwire` reads it back.

The file holds ``T_Probe_Image`` (rigid, metres) with its pixel spacing (``spacing_mm``), PLUS's
affine Image→Probe in millimetres (``affine_mm``, as PLUS writes it) with the pixel sizes it implies,
the angle between the two models' rotations, the point counts, per model the 3D reprojection
errors (all points and the best 95 %, as PLUS reports them) on the validation and calibration
frames and the per-wire 2D errors in pixels, and the SHA-256 of both inputs. Added within the same
format (readers of the first files ignore them; :func:`read_nwire` reads files without them): the
chosen ``model`` and why, and ``models``: every model's Image→Probe matrix (PLUS's form, mm).
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from brachycal._lazy import renamed
from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.phantom.nwire import (
    NWireResult,
    best_fraction,
    calibrate_nwire,
    fit_affine,
    matrix_wire_errors_2d,
    rotation_difference_deg,
    wire_point_pairs,
)
from brachycal.calibration.phantom.nwire_refine import PLUS_NAMES, REFINEMENTS, Refinement, observations, refine_all
from brachycal.data.formats.metaimage import MF_FRAME_TEXT
from brachycal.data.formats.plus_files import PlusConfig, SegmentedFrame, read_plus_config, read_segmented_frames
from brachycal.data.json_schema import (
    Obj,
    array,
    image_to_probe_mm,
    mapping,
    number,
    read_document,
    spacing,
    text,
    transform,
)
from brachycal.errors import InputError
from brachycal.io import sha256_file, write_json
from brachycal.se3 import FloatArray

FORMAT = "brachycal-nwire/1"
#: The image models fitted and validated: PLUS's affine matrix, a rotation with two spacings, and
#: PLUS fCal's four refinements (:data:`~brachycal.calibration.phantom.nwire_refine.REFINEMENTS`).
NWIRE_MODELS = ("affine", "rigid", *REFINEMENTS)
#: How the default model is chosen (written to the result).
CHOSEN_BY_VALIDATION = "lowest best-95% validation mean"
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
class NWireFileResult:
    """An N-wire calibration of PLUS files and its validation.

    Attributes:
        calibration: the fitted models (rigid ``T_Ptip_I`` with spacings, and PLUS's affine).
        models: model (:data:`NWIRE_MODELS`) → its validation.
        calibration_points, validation_points: middle-wire points used to fit and to validate.
        frames_used, frames_total: calibration frames whose segmentation is usable, and all of them.
        validation_frames: validation frames in the file.
        start_spacing_m: the spacing the fit started from (the configuration's, metres per pixel).
        inputs: file name → SHA-256 of the configuration and the frames file.
        refinements: PLUS fCal's refined models by name (:mod:`~brachycal.calibration.phantom.nwire_refine`).
        model: the chosen model (:data:`NWIRE_MODELS`), and ``chosen_by`` how it was chosen.
    """

    calibration: NWireResult
    models: dict[str, ModelValidation]
    calibration_points: int
    validation_points: int
    frames_used: int
    frames_total: int
    validation_frames: int
    start_spacing_m: float
    inputs: dict[str, str]
    refinements: dict[str, Refinement] = field(default_factory=dict)
    model: str = "affine"
    chosen_by: str = CHOSEN_BY_VALIDATION

    def matrix(self, model: str | None = None) -> FloatArray:
        """``model``'s (default: the chosen one's) Image→Probe ``(4, 4)``, pixels → metres, PLUS's form."""
        model = model or self.model
        if model in self.refinements:
            return self.refinements[model].matrix
        return self.calibration.matrix(model)

    @property
    def affine_spacing_m(self) -> FloatArray:
        """``(2,)`` pixel sizes the affine model implies (lengths of its u and v columns), metres."""
        return np.linalg.norm(self.calibration.affine[:3, :2], axis=0)

    @property
    def rigid_vs_affine_deg(self) -> float:
        """Angle between the rigid and the affine models' rotations, degrees."""
        return rotation_difference_deg(self.calibration.T_Ptip_I, self.calibration.affine)

    def to_json(self) -> dict[str, object]:
        """The ``brachycal-nwire/1`` payload (metres; ``*_mm`` and ``*_px`` where the key says)."""
        c = self.calibration
        affine_mm = c.affine.copy()
        affine_mm[:3, :] *= 1e3
        return {
            "format": FORMAT,
            "pixel_frame": MF_FRAME_TEXT,
            "T_Probe_Image": c.T_Ptip_I.tolist(),
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
            "model": self.model,
            "model_chosen_by": self.chosen_by,
            "models": {model: self._model_json(model) for model in self.models},
            "inputs": self.inputs,
        }

    def _model_json(self, model: str) -> dict[str, object]:
        """One model's Image→Probe (PLUS's form, pixels → mm) and how it was fitted."""
        M = self.matrix(model)
        M[:3, :] *= 1e3
        out: dict[str, object] = {
            "image_to_probe_mm": M.tolist(),
            "spacing_mm": (np.linalg.norm(M[:3, :2], axis=0)).tolist(),
        }
        if model in self.refinements:
            r = self.refinements[model]
            cost, isotropic = REFINEMENTS[model]
            out |= {
                "plus_name": PLUS_NAMES[model],
                "cost": cost,
                "isotropic_spacing": isotropic,
                "start": r.start,
                "frames": r.frames,
                "cost_rms": r.cost_rms * (1e3 if cost == "3d" else 1.0),
                "cost_unit": "mm" if cost == "3d" else "px",
            }
        return out


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


def check_model(model: str | None) -> None:
    """Refuse a ``model`` that is not None nor a :data:`NWIRE_MODELS` name.

    Raises:
        InputError: an unknown model, naming the known ones.
    """
    if model is not None and model not in NWIRE_MODELS:
        raise InputError(f"no N-wire model {model!r}: expected one of {', '.join(NWIRE_MODELS)}")


def calibrate_nwire_files(
    config_path: str | os.PathLike[str], frames_path: str | os.PathLike[str], *, model: str | None = None
) -> NWireFileResult:
    """Calibrate Image → Probe from a PLUS configuration and segmented frames, and validate every model.

    Fits PLUS's linear model, brachycal's rigid + u/v spacings model and PLUS fCal's four refinements
    (:mod:`~brachycal.calibration.phantom.nwire_refine`) on the calibration frames, and reports each on the
    validation frames as PLUS does. The chosen model is ``model``, or (None) the one with the lowest
    mean 3D error over the best 95 % of the validation points — PLUS's own validation figure; the
    calibration frames alone decide every fit, the validation frames only this choice.

    Args:
        config_path: PLUS device-set configuration XML (phantom wires, Phantom→Reference).
        frames_path: PLUS segmented-frames XML (calibration and validation frames).
        model: a :data:`NWIRE_MODELS` name to choose, or None to choose by validation error.

    Raises:
        InputError: a file is unreadable or malformed, or has no usable validation frame; an unknown model.
        DegenerateDataError: the middle-wire points cannot determine a fit.
    """
    check_model(model)  # before the files are read
    config = read_plus_config(config_path)
    calibration_frames, validation_frames = read_segmented_frames(frames_path)
    return calibrate_nwire_frames(
        config,
        calibration_frames,
        validation_frames,
        model=model,
        inputs={Path(p).name: sha256_file(p) for p in (config_path, frames_path)},
    )


def calibrate_nwire_frames(
    config: PlusConfig,
    calibration_frames: list[SegmentedFrame],
    validation_frames: list[SegmentedFrame],
    *,
    model: str | None = None,
    inputs: dict[str, str] | None = None,
) -> NWireFileResult:
    """:func:`calibrate_nwire_files` of frames already read (``config`` holds the phantom registration).

    Args:
        inputs: file name → SHA-256 recorded in the result.

    Raises:
        InputError: an unknown model, no usable validation frame, a frame the fits refuse.
        DegenerateDataError: the middle-wire points cannot determine a fit.
    """
    check_model(model)
    uv, p_probe, _ = wire_point_pairs(config, calibration_frames)
    start_spacing = config.approximate_spacing_m or FALLBACK_SPACING_M
    calibration = calibrate_nwire(uv, p_probe, start_spacing)
    if not any(f.usable for f in validation_frames):
        source = validation_frames[0].source if validation_frames else None
        raise InputError("no usable validation frames", file=source)
    uv_v, p_v, _ = wire_point_pairs(config, validation_frames)
    refinements = refine_all(observations(config, calibration_frames), calibration, fit_affine(uv, p_probe)[1])
    matrices = {name: calibration.matrix(name) for name in ("affine", "rigid")}
    matrices |= {name: r.matrix for name, r in refinements.items()}
    models = {}
    for name, M in matrices.items():
        wires = matrix_wire_errors_2d(M, config, validation_frames)
        models[name] = ModelValidation(
            validation_3d=ErrorStats.between(p_v, _to_probe(M, uv_v)),
            calibration_3d=ErrorStats.between(p_probe, _to_probe(M, uv)),
            wires_2d={name: WireErrors(e.mean(axis=0), e.std(axis=0), len(e)) for name, e in wires.items()},
        )
    chosen = model or min(models, key=lambda name: models[name].validation_best95.mae_mm)
    return NWireFileResult(
        calibration=calibration,
        models=models,
        calibration_points=len(uv),
        validation_points=len(uv_v),
        frames_used=sum(f.usable for f in calibration_frames),
        frames_total=len(calibration_frames),
        validation_frames=len(validation_frames),
        start_spacing_m=start_spacing,
        inputs=dict(inputs or {}),
        refinements=refinements,
        model=chosen,
        chosen_by="--model" if model is not None else CHOSEN_BY_VALIDATION,
    )


def _to_probe(image_to_probe: FloatArray, uv_px: FloatArray) -> FloatArray:
    """Pixels ``(N, 2)`` in the image plane mapped by an Image→Probe ``(4, 4)``, metres ``(N, 3)``."""
    return uv_px @ image_to_probe[:3, :2].T + image_to_probe[:3, 3]


def write_nwire(run: NWireFileResult, path: str | os.PathLike[str], *, force: bool = False) -> Path:
    """Write ``run`` as ``brachycal-nwire/1`` JSON, all or nothing (never NaN).

    Raises:
        OutputError: the file exists (without ``force``), cannot be written, or holds a NaN.
    """
    return write_json(path, run.to_json(), force=force)


#: The schema of a ``brachycal-nwire/1`` document (:mod:`brachycal.data.json_schema`): the keys
#: :func:`read_nwire` uses, in metres (``T_Probe_Image``) and PLUS's pixels → mm (``*_mm`` matrices).
NWIRE_DOCUMENT = Obj(
    required={"T_Probe_Image": transform, "spacing_mm": spacing, "affine_mm": image_to_probe_mm},
    optional={
        "affine_spacing_mm": array(number(0.0, unit="mm/px"), length=2),
        "rigid_vs_affine_deg": number(0.0, 180.0, "deg"),
        "model": text(nonempty=True),
        "models": mapping(
            Obj(required={"image_to_probe_mm": image_to_probe_mm}, optional={"spacing_mm": spacing}),
            keys=NWIRE_MODELS,
        ),
        "inputs": mapping(text()),
    },
)


@dataclass(frozen=True)
class NWireFile:
    """What a ``brachycal-nwire/1`` file holds.

    Attributes:
        T_Ptip_I: ``(4, 4)`` rigid Image → Probe, metres.
        spacing_m: ``(2,)`` its pixel spacing, metres per pixel.
        affine: ``(4, 4)`` PLUS's affine Image → Probe, metres (pixels in, metres out).
        raw: the whole payload (errors, counts, input hashes).
        model: the chosen model (``"rigid"`` in files written before models were chosen).
        models: model → its Image→Probe ``(4, 4)``, pixels → metres (empty in those files).
    """

    T_Ptip_I: FloatArray
    spacing_m: FloatArray
    affine: FloatArray
    raw: dict
    model: str = "rigid"
    models: dict[str, FloatArray] = field(default_factory=dict)

    @property
    def T_probe_image(self) -> FloatArray:
        """Deprecated spelling of :attr:`T_Ptip_I` (kept one release)."""
        warnings.warn("T_probe_image is deprecated: use T_Ptip_I", DeprecationWarning, stacklevel=2)
        return self.T_Ptip_I

    @property
    def image_to_probe(self) -> FloatArray:
        """The chosen model's Image→Probe ``(4, 4)``, pixels → metres (PLUS's form)."""
        if self.model in self.models:
            return self.models[self.model]
        M = self.T_Ptip_I.copy()
        M[:3, :3] = M[:3, :3] * np.array([*self.spacing_m, self.spacing_m.mean()])
        return M


def read_nwire(path: str | os.PathLike[str]) -> NWireFile:
    """Read a ``brachycal-nwire/1`` file back.

    Raises:
        InputError: not readable JSON, another format, or a value :data:`NWIRE_DOCUMENT` refuses: a
            ``T_Probe_Image`` that is not rigid, a spacing that is not plausible, an Image→Probe
            matrix that is sheared or out of range (naming the file and the key).
    """
    path = Path(path)
    raw = read_document(path, FORMAT, NWIRE_DOCUMENT)
    T = np.array(raw["T_Probe_Image"], dtype=float)
    spacing_m = np.array(raw["spacing_mm"], dtype=float) * 1e-3
    affine = np.array(raw["affine_mm"], dtype=float)
    affine[:3, :] *= 1e-3
    models: dict[str, FloatArray] = {}
    for name, entry in raw.get("models", {}).items():
        M = np.array(entry["image_to_probe_mm"], dtype=float)
        M[:3, :] *= 1e-3
        models[str(name)] = M
    model = raw.get("model", "rigid")
    if models and model not in models:
        raise InputError(f"must name one of the file's models, got {model!r}", file=path, column="model")
    return NWireFile(T, spacing_m, affine, raw, model, models)


#: Former names, given for one release with a DeprecationWarning.
if not TYPE_CHECKING:  # type checkers see only the new names
    __getattr__ = renamed(
        __name__,
        {"NWireRun": "NWireFileResult", "StoredNWire": "NWireFile", "nwire_from_files": "calibrate_nwire_files"},
    )
