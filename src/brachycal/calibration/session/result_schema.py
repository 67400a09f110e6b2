"""The schema of a ``brachycal-result/1`` document: every key the writer lays out, its type, shape
and physical range, checked before anything in the file is used.

Design: ``docs/design/files.md``, "The result file's schema".
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from brachycal.calibration.labels import METHODS
from brachycal.data.json_files import check_json_tree, json_place, shown
from brachycal.errors import InputError
from brachycal.validate import MAX_IMAGE_PX, check_int, check_range, check_spacing_mm, check_transform

FORMAT = "brachycal-result/1"

#: Registration methods a result stores an image calibration for: Table II's and the whole chain's.
RESULT_METHODS = (*METHODS, "chain")

#: Largest translation of a stored transform (and of a reference tip, a joint-origin correction),
#: metres: the tools, the image and the joint origins are within a metre of their parent frames
#: (the SDA10F's arms reach 0.7 m); 5 m is no robot cell's, and a value in millimetres is refused.
MAX_TRANSLATION_M = 5.0

#: Largest joint zero offset and joint-origin rotation correction, radians: beyond a half turn an
#: angle is another zero plus whole turns, never a correction (1e6 rad would move a point by cm).
MAX_JOINT_CORRECTION_RAD = math.pi

#: Plausible speeds of sound, m/s: from air-filled foams (~340) to bone (~4000); soft tissue and
#: water are near 1500.
SOUND_SPEED_RANGE_M_S = (300.0, 5000.0)

#: Largest number of samples, folds or replicates a result counts (a day at the robot is ~1e4 poses).
MAX_COUNT = 10**7


@dataclass(frozen=True)
class Where:
    """The file being checked and a place inside its document."""

    file: str | os.PathLike[str] | None
    place: str

    def at(self, key: str | int) -> Where:
        return Where(self.file, json_place(self.place, key))

    def refuse(self, problem: str) -> InputError:
        return InputError(problem, file=self.file, column=self.place or None)


#: A check of one value at a place: returns nothing, raises :class:`InputError` naming the place.
Spec = Callable[[Any, Where], None]


def _kind(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true/false"
    if isinstance(value, int | float):
        return "a number"
    if isinstance(value, str):
        return "a string"
    return "a list" if isinstance(value, list) else "an object" if isinstance(value, dict) else type(value).__name__


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


# ---------------------------------------------------------------------------------------------
# The building blocks


def number(low: float | None = None, high: float | None = None, unit: str = "", *, low_open: bool = False) -> Spec:
    """A finite JSON number within ``[low, high]`` (:func:`~brachycal.validate.check_range`)."""

    def check(value: Any, where: Where) -> None:
        if not _is_number(value):
            raise where.refuse(f"must be a number, got {_kind(value)}")
        try:
            check_range(value, "", low=low, high=high, low_open=low_open, unit=unit)
        except InputError as exc:
            raise where.refuse(exc.problem) from None

    return check


def integer(low: int = 0, high: int = MAX_COUNT) -> Spec:
    """A whole JSON number within ``[low, high]`` (:func:`~brachycal.validate.check_int`)."""

    def check(value: Any, where: Where) -> None:
        if not _is_number(value):
            raise where.refuse(f"must be a whole number, got {_kind(value)}")
        try:
            check_int(value, "", low=low, high=high)
        except InputError as exc:
            raise where.refuse(exc.problem) from None

    return check


def text(*, nonempty: bool = False) -> Spec:
    """A JSON string (not empty with ``nonempty``)."""

    def check(value: Any, where: Where) -> None:
        what = "a non-empty string" if nonempty else "a string"
        if not isinstance(value, str):
            raise where.refuse(f"must be {what}, got {_kind(value)}")
        if nonempty and not value:
            raise where.refuse(f"must be {what}, got an empty one")

    return check


def nullable(spec: Spec) -> Spec:
    """``null`` or what ``spec`` accepts."""

    def check(value: Any, where: Where) -> None:
        if value is not None:
            spec(value, where)

    return check


def array(item: Spec, *, length: int | None = None, nonempty: bool = False) -> Spec:
    """A JSON list whose every item ``item`` accepts (of ``length`` items when given)."""

    def check(value: Any, where: Where) -> None:
        if not isinstance(value, list):
            raise where.refuse(f"must be a list, got {_kind(value)}")
        if length is not None and len(value) != length:
            raise where.refuse(f"must hold {length} values, got {len(value)}")
        if nonempty and not value:
            raise where.refuse("must not be empty")
        for k, entry in enumerate(value):
            item(entry, where.at(k))

    return check


def mapping(value: Spec, *, keys: tuple[str, ...] | None = None, nonempty: bool = False) -> Spec:
    """A JSON object of names (each among ``keys`` when given) to values ``value`` accepts."""

    def check(raw: Any, where: Where) -> None:
        if not isinstance(raw, dict):
            raise where.refuse(f"must be an object (name: value), got {_kind(raw)}")
        if nonempty and not raw:
            raise where.refuse("must not be empty")
        for key, entry in raw.items():
            if not key or (keys is not None and key not in keys):
                known = f" (known: {', '.join(keys)})" if keys is not None else ""
                raise where.refuse(f"unknown name {shown(key)}{known}")
            value(entry, where.at(key))

    return check


@dataclass(frozen=True)
class Obj:
    """A JSON object with the ``required`` and ``optional`` keys (others are accepted unchecked,
    unless ``closed``)."""

    required: Mapping[str, Spec] = field(default_factory=dict)
    optional: Mapping[str, Spec] = field(default_factory=dict)
    closed: bool = False

    def __call__(self, raw: Any, where: Where) -> None:
        if not isinstance(raw, dict):
            raise where.refuse(f"must be an object, got {_kind(raw)}")
        for key, spec in self.required.items():
            if key not in raw:
                raise where.at(key).refuse("missing")
            spec(raw[key], where.at(key))
        for key, spec in self.optional.items():
            if key in raw:
                spec(raw[key], where.at(key))
        if self.closed:
            extra = sorted(set(raw) - set(self.required) - set(self.optional))
            if extra:
                raise where.refuse(
                    f"unknown key {shown(extra[0])} (it holds {', '.join([*self.required, *self.optional])})"
                )


def transform(value: Any, where: Where) -> None:
    """A rigid 4x4 transform (rows of numbers, metres): finite, last row 0 0 0 1, a proper rotation
    (:func:`~brachycal.validate.check_transform`), its translation within :data:`MAX_TRANSLATION_M`."""
    array(array(number(), length=4), length=4)(value, where)
    try:
        T = check_transform(np.array(value, dtype=float), "4x4 matrix")
    except InputError as exc:
        raise where.refuse(exc.problem) from None
    reach = float(np.max(np.abs(T[:3, 3])))
    if reach > MAX_TRANSLATION_M:
        raise where.refuse(
            f"translation of {reach:g} m: beyond {MAX_TRANSLATION_M:g} m from its parent frame "
            "(millimetres given as metres?)"
        )


def spacing(value: Any, where: Where) -> None:
    """A pixel spacing ``[s_u, s_v]``, mm/px (:func:`~brachycal.validate.check_spacing_mm`)."""
    array(number(), length=2)(value, where)
    check_spacing_mm(value, "", file=where.file, column=where.place)


def image_size(value: Any, where: Where) -> None:
    """``[width, height]``: whole pixels in ``[1, MAX_IMAGE_PX]``."""
    try:
        array(integer(1, MAX_IMAGE_PX), length=2)(value, where)
    except InputError:
        raise where.refuse(
            f"must be two whole numbers of pixels in [1, {MAX_IMAGE_PX}] (width, height), got {shown(value)}"
        ) from None


# ---------------------------------------------------------------------------------------------
# The document

position_m = array(number(-MAX_TRANSLATION_M, MAX_TRANSLATION_M, "m"), length=3)
length_mm = number(0.0, unit="mm")
sd_deg = number(0.0, unit="deg")
angle_deg = number(0.0, 180.0, "deg")
sha256 = text()

#: Figures of a set of 3D errors (``loocv``, ``fit_residuals``, ``mechanical``), millimetres.
ERRORS: dict[str, Spec] = {
    "n": integer(),
    "mae_mm": length_mm,
    "rmse_mm": length_mm,
    "sd_mm": length_mm,
    "max_mm": length_mm,
    "errors_mm": array(length_mm),
}
errors = Obj(optional=ERRORS)
tool = Obj(
    optional={
        **ERRORS,
        "axes_angle_deg": angle_deg,
        "axes_angle_sd_deg": sd_deg,
        "predicted_tip_sd_mm": length_mm,
        "predicted_rotation_sd_deg": sd_deg,
    }
)
predicted = Obj(
    optional={
        "noise_sd_mm": length_mm,
        "rotation_sd_deg": sd_deg,
        "origin_sd_mm": length_mm,
        "spacing_sd_mm": array(length_mm, length=2),
        "samples_sd_mm": length_mm,
        "reach_sd_mm": length_mm,
    }
)
accuracy = Obj(
    optional={
        "joint_translation_sd_mm": length_mm,
        "joint_rotation_sd_deg": sd_deg,
        "encoder_sd_deg": sd_deg,
        "source": text(),
    }
)
correction = Obj(
    optional={
        **{v: number(-MAX_TRANSLATION_M, MAX_TRANSLATION_M, "m") for v in ("vx", "vy", "vz")},
        **{w: number(-MAX_JOINT_CORRECTION_RAD, MAX_JOINT_CORRECTION_RAD, "rad") for w in ("wx", "wy", "wz")},
    },
    closed=True,
)
rmse_by_name = mapping(length_mm)
numbers = array(number())

#: The sections a whole-chain result moves under ``sequential`` (and the top level holds).
METHOD_SECTIONS: dict[str, Spec] = {
    "transforms": Obj(
        required={
            "ER_T_Ntip": transform,
            "EL_T_Ptip": transform,
            "Ptip_T_I": mapping(transform, keys=RESULT_METHODS, nonempty=True),
        }
    ),
    "spacing_mm": mapping(spacing, keys=RESULT_METHODS),
    "loocv": mapping(errors, keys=RESULT_METHODS),
    "fit_residuals": mapping(errors, keys=RESULT_METHODS),
    "predicted_uncertainty": mapping(predicted, keys=RESULT_METHODS),
}

CHAIN = Obj(
    optional={
        "model": text(),
        "model_selection": Obj(
            optional={
                "rule": text(),
                "folds": integer(),
                "scored_samples": integer(),
                "evidence": mapping(mapping(nullable(length_mm))),
                "undetermined": mapping(text()),
            }
        ),
        "sound_speed_m_s": nullable(number(*SOUND_SPEED_RANGE_M_S, "m/s")),
        "noise_sd_mm": rmse_by_name,
        "noise": mapping(Obj(optional={"sd_mm": length_mm, "residual_dof": number(0.0), "source": text()})),
        "image_noise_along_axes": mapping(Obj(optional={"sd_mm": length_mm, "residual_dof": number(0.0)})),
        "outliers": array(text()),
        "outlier_rule": text(),
        "fitted_samples": integer(),
        "intervals_95": mapping(Obj(optional={"low": numbers, "value": numbers, "high": numbers})),
        "intervals_contain": text(),
        "robot_accuracy": nullable(accuracy),
        "noise_share_after_robot": mapping(number(0.0, 1.0)),
        "conditioning": Obj(
            optional={
                "rcond": nullable(number(0.0)),
                "rcond_limit": number(0.0),
                "rotation_sd_deg": mapping(sd_deg),
                "rotation_sd_limit_deg": sd_deg,
            }
        ),
        "predicted_landing_rms_mm": Obj(
            optional={
                "samples": Obj(optional={"mean": length_mm, "max": length_mm, "per_sample": array(length_mm)}),
                "image_map": Obj(
                    optional={
                        "pixels": array(array(number(-0.5, MAX_IMAGE_PX, "px"), length=2)),
                        "rms_mm": array(length_mm),
                    }
                ),
                "warn_above_mm": length_mm,
            }
        ),
        "bootstrap_replicates": integer(),
        "joint_offsets_rad": mapping(number(-MAX_JOINT_CORRECTION_RAD, MAX_JOINT_CORRECTION_RAD, "rad")),
        "robot_identification": Obj(
            optional={
                "parameterisation": text(),
                "corrections": mapping(correction),
                "prior": accuracy,
                "identified_combinations": integer(),
                "structural_rank": integer(),
                "not_identifiable": mapping(text()),
                "held_out_configurations": Obj(
                    optional={"folds": integer(), "image_rmse_mm": rmse_by_name, "image_mae_mm": rmse_by_name}
                ),
            }
        ),
        "robot_joint_origins": mapping(Obj(required={"urdf": transform, "corrected": transform}, closed=True)),
    }
)

DOCUMENT = Obj(
    required={"format": text(), "transforms": METHOD_SECTIONS["transforms"]},
    optional={
        **{k: v for k, v in METHOD_SECTIONS.items() if k != "transforms"},
        "mechanical": Obj(optional={"needle": tool, "probe": tool}),
        "reference_tips_m": mapping(position_m),
        "reference_tips_sd_mm": mapping(length_mm),
        "samples": array(text()),
        "image": Obj(optional={"size_px": image_size}),
        "inputs": mapping(sha256),
        "robot_model": Obj(optional={"urdf": text(), "sha256": sha256}),
        "robot": Obj(
            required={
                "name": text(nonempty=True),
                "description": text(),
                "description_sha256": sha256,
                "urdf_sha256": sha256,
                "joint_names": array(text(nonempty=True), nonempty=True),
            }
        ),
        "software": mapping(text()),
        "chain": CHAIN,
        "sequential": Obj(optional=METHOD_SECTIONS),
        "refused": mapping(text()),
        "nominal_spacing_mm": spacing,
        "update": Obj(),
    },
)


def validate_result_document(doc: Any, path: str | os.PathLike[str] | None = None) -> dict[str, Any]:
    """``doc`` (a parsed ``brachycal-result/1`` file) if every key the writer lays out has its type,
    shape and range, and every value anywhere is finite (module docstring).

    Args:
        doc: the parsed JSON document.
        path: the file it was read from, for the refusal.

    Raises:
        InputError: the first problem, naming ``path`` and the place in the document
            (``column 'transforms.Ptip_T_I.kabsch'``).
    """
    check_json_tree(doc, path)
    top = Where(path, "")
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        found = doc.get("format") if isinstance(doc, dict) else None
        raise top.at("format").refuse(f"format is {shown(found)}, expected {FORMAT!r}")
    DOCUMENT(doc, top)
    images = doc["transforms"]["Ptip_T_I"]
    spacings = doc.get("spacing_mm", {})
    for method in images:
        if method not in spacings:
            raise top.at("spacing_mm").at(method).refuse("missing pixel spacing")
    return doc
