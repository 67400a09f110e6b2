"""The schema of a ``brachycal-result/1`` document: every key the writer lays out, its type, shape
and physical range, checked before anything in the file is used (the building blocks and the one
check every result file goes through: :mod:`brachycal.data.json_schema`).

Design: ``docs/design/files.md``, "The result file's schema".
"""

from __future__ import annotations

import math
import os
from typing import Any

from brachycal.calibration.labels import METHODS
from brachycal.data.json_schema import (
    MAX_TRANSLATION_M,
    Obj,
    Spec,
    Where,
    array,
    image_size,
    integer,
    mapping,
    nullable,
    number,
    spacing,
    text,
    transform,
    validate_document,
)
from brachycal.validate import MAX_IMAGE_PX

FORMAT = "brachycal-result/1"

#: Registration methods a result stores an image calibration for: Table II's and the whole chain's.
RESULT_METHODS = (*METHODS, "chain")

#: Largest joint zero offset and joint-origin rotation correction, radians: beyond a half turn an
#: angle is another zero plus whole turns, never a correction (1e6 rad would move a point by cm).
MAX_JOINT_CORRECTION_RAD = math.pi

#: Plausible speeds of sound, m/s: from air-filled foams (~340) to bone (~4000); soft tissue and
#: water are near 1500.
SOUND_SPEED_RANGE_M_S = (300.0, 5000.0)


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
    validate_document(doc, path, FORMAT, DOCUMENT)
    top = Where(path, "")
    images = doc["transforms"]["Ptip_T_I"]
    spacings = doc.get("spacing_mm", {})
    for method in images:
        if method not in spacings:
            raise top.at("spacing_mm").at(method).refuse("missing pixel spacing")
    return doc
