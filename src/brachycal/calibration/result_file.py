"""Calibration result, format ``brachycal-result/1`` (a JSON file; CONVENTIONS.md).

Transforms are 4×4 row-major lists in metres. Besides the keys of the conventions
(``transforms``, ``mechanical``, ``loocv``, ``inputs``), the file carries the pixel spacing each
registration method goes with (``spacing_mm``), the reference tips, fit residuals, the samples'
names, the tool-axes angles, and the software versions that produced it.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from brachycal.calibration.image_to_probe import METHODS, ImageCalibration
from brachycal.calibration.sequential import CalibrationResult
from brachycal.errors import InputError
from brachycal.files import atomic_open
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray, is_rigid

FORMAT = "brachycal-result/1"


def to_json(result: CalibrationResult, *, robot_source: str = "", robot_sha256: str = "", chain=None) -> dict:
    """The result as a JSON-ready dict.

    With ``chain`` (a :class:`~brachycal.calibration.chain_report.ChainReport`), the transforms
    are the whole-chain method's (``Ptip_T_I`` and ``spacing_mm`` under ``"chain"``), its section
    ``chain`` is added, and the sequential method's transforms and figures stay under
    ``sequential`` for comparison (they go with its own ``EL_T_Ptip``).
    """
    import pinocchio

    from brachycal import __version__

    def tool(calibration) -> dict:
        out = calibration.validation.as_dict(with_errors=True)
        out["axes_angle_deg"] = calibration.rotation.axes_angle_deg
        return out

    payload = {
        "format": FORMAT,
        "transforms": {
            "ER_T_Ntip": result.T_ER_Ntip.tolist(),
            "EL_T_Ptip": result.T_EL_Ptip.tolist(),
            "Ptip_T_I": {m: c.T_Ptip_I.tolist() for m, c in result.image.items()},
        },
        "spacing_mm": {m: (c.spacing_m * 1e3).tolist() for m, c in result.image.items()},
        "mechanical": {"needle": tool(result.needle), "probe": tool(result.probe)},
        "loocv": {m: s.as_dict(with_errors=True) for m, s in result.loocv.items()},
        "fit_residuals": {m: s.as_dict() for m, s in result.fit_residuals.items()},
        "reference_tips_m": {k: v.tolist() for k, v in result.p_R_Rtip.items()},
        "samples": result.sample_ids,
        "inputs": result.inputs,
        "robot_model": {"urdf": robot_source, "sha256": robot_sha256},
        "software": {"brachycal": __version__, "pinocchio": pinocchio.__version__, "numpy": np.__version__},
    }
    if chain is None:
        return payload
    from brachycal.calibration.chain_report import chain_json

    sequential = {k: payload.pop(k) for k in ("transforms", "spacing_mm", "loocv", "fit_residuals")}
    fit = chain.fit
    payload["transforms"] = {
        "ER_T_Ntip": fit.T_ER_Ntip.tolist(),
        "EL_T_Ptip": fit.T_EL_Ptip.tolist(),
        "Ptip_T_I": {"chain": fit.image.T_Ptip_I.tolist()},
    }
    payload["spacing_mm"] = {"chain": (fit.image.spacing_m * 1e3).tolist()}
    payload["loocv"] = {"chain": chain.loocv.as_dict(with_errors=True)}
    payload["chain"] = chain_json(chain, result.sample_ids)
    payload["sequential"] = sequential
    return payload


def write_result(
    result: CalibrationResult,
    path: str | os.PathLike[str],
    *,
    force: bool = False,
    robot_source: str = "",
    robot_sha256: str = "",
    chain=None,
) -> Path:
    """Write the result atomically; never replaces an existing file unless ``force``."""
    payload = to_json(result, robot_source=robot_source, robot_sha256=robot_sha256, chain=chain)
    with atomic_open(path, force=force) as handle:
        json.dump(payload, handle, indent=2)
        handle.write("\n")
    return Path(path)


@dataclass(frozen=True)
class StoredCalibration:
    """What targeting needs from a result file."""

    T_ER_Ntip: FloatArray
    T_EL_Ptip: FloatArray
    image: dict[str, ImageCalibration]
    raw: dict
    joint_offsets_rad: dict[str, float] = field(default_factory=dict)

    def software_robot(self, robot: Robot) -> Robot:
        """The robot model to compute and command with: ``robot`` with the estimated joint offsets."""
        return robot.with_joint_offsets(self.joint_offsets_rad) if self.joint_offsets_rad else robot


def _matrix(value: object, path: Path, key: str) -> FloatArray:
    try:
        T = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError("not a 4x4 matrix of numbers", file=path, column=key) from None
    if T.shape != (4, 4) or not np.all(np.isfinite(T)) or not is_rigid(T, tol=1e-6):
        raise InputError("not a rigid 4x4 transform", file=path, column=key)
    return T


def read_result(path: str | os.PathLike[str]) -> StoredCalibration:
    """Read a result file back; refuses anything that is not a valid ``brachycal-result/1``."""
    path = Path(path)
    try:
        raw = json.loads(path.read_text())
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror})", file=path) from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"not valid JSON ({exc})", file=path) from None
    if not isinstance(raw, dict) or raw.get("format") != FORMAT:
        found = raw.get("format") if isinstance(raw, dict) else None
        raise InputError(f"format is {found!r}, expected {FORMAT!r}", file=path, column="format")
    transforms = raw.get("transforms", {})
    images = transforms.get("Ptip_T_I", {}) if isinstance(transforms, dict) else {}
    if not isinstance(images, dict) or not images:
        raise InputError("no image transforms", file=path, column="transforms.Ptip_T_I")
    image = {}
    for method, T in images.items():
        if method not in (*METHODS, "chain"):
            raise InputError(f"unknown method {method!r}", file=path, column="transforms.Ptip_T_I")
        spacing = np.array(raw.get("spacing_mm", {}).get(method, [np.nan, np.nan]), dtype=float) * 1e-3
        if spacing.shape != (2,) or not np.all(spacing > 0):
            raise InputError("missing or invalid pixel spacing", file=path, column=f"spacing_mm.{method}")
        image[method] = ImageCalibration(method, _matrix(T, path, f"transforms.Ptip_T_I.{method}"), spacing)
    return StoredCalibration(
        T_ER_Ntip=_matrix(transforms.get("ER_T_Ntip"), path, "transforms.ER_T_Ntip"),
        T_EL_Ptip=_matrix(transforms.get("EL_T_Ptip"), path, "transforms.EL_T_Ptip"),
        image=image,
        raw=raw,
        joint_offsets_rad={str(k): float(v) for k, v in raw.get("chain", {}).get("joint_offsets_rad", {}).items()},
    )
