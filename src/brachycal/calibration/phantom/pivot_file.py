"""Pivot calibration of a pose-list file, and its result file ``brachycal-pivot/1`` (JSON).

:func:`calibrate_pivot_files` reads a pose list (:mod:`brachycal.data.pose_list`), runs the estimator
of :mod:`brachycal.calibration.phantom.pivot` and hashes the input; :func:`write_pivot` writes the result
and :func:`read_pivot` reads it back. Lengths are in the units of the poses, which the file
records (``units``: ``"m"`` or ``"mm"``); ``tip_in_tool`` is the tip in the tool's (marker's or
flange's) frame, ``pivot_in_reference`` the fixed pivot point in the reference frame.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from brachycal._lazy import renamed
from brachycal.calibration.labels import PIVOT_METHODS as PIVOT_METHOD_NAMES
from brachycal.calibration.labels import POSE_UNITS
from brachycal.calibration.phantom.pivot import PivotResult, pivot_algebraic, pivot_robust
from brachycal.data.json_schema import MAX_TRANSLATION_M, Obj, Where, array, number, one_of, read_document
from brachycal.data.pose_list import read_pose_list
from brachycal.errors import DegenerateDataError, InputError
from brachycal.io import sha256_file, write_json
from brachycal.se3 import FloatArray
from brachycal.validate import TOOL_LENGTH_M_RANGE

FORMAT = "brachycal-pivot/1"
#: Estimators by name (``brachycal pivot --method``).
PIVOT_METHODS = dict(zip(PIVOT_METHOD_NAMES, (pivot_algebraic, pivot_robust), strict=True))
#: Units a pose list's translations may be in.
UNITS = POSE_UNITS


@dataclass(frozen=True)
class PivotFileResult:
    """A pivot calibration of one pose list: the estimate, the poses' names, the units, the input hash.

    Attributes:
        result: the estimate (tip, pivot, residuals, inliers, predicted SDs), in ``units``.
        pose_names: ``(N,)`` each pose's key (the list's first column) or file row.
        units: ``"m"`` or ``"mm"``, the units of the poses' translations and so of every length here.
        inputs: file name → SHA-256 of the pose list.
    """

    result: PivotResult
    pose_names: list[str]
    units: str
    inputs: dict[str, str]

    @property
    def outliers(self) -> list[str]:
        """Names of the poses the estimator left out (none for the algebraic method)."""
        return [name for name, inlier in zip(self.pose_names, self.result.inliers, strict=True) if not inlier]

    def to_json(self) -> dict[str, object]:
        """The ``brachycal-pivot/1`` payload (lengths in :attr:`units`)."""
        r = self.result
        return {
            "format": FORMAT,
            "method": r.method,
            "units": self.units,
            "tip_in_tool": r.p_marker_tip.tolist(),
            "pivot_in_reference": r.p_ref_pivot.tolist(),
            "rms_per_axis": r.rms_per_axis,
            "rms_3d": r.rms_3d,
            # Predicted 3D SDs from the residual and the rotations' spread (brachycal.calibration.phantom.pivot).
            "tip_sd": r.tip_sd,
            "pivot_sd": r.pivot_sd,
            "noise_sd_per_axis": r.noise_sd,
            "rotation_spread_deg": r.rotation_spread_deg,
            "n_poses": len(self.pose_names),
            "n_inliers": int(r.inliers.sum()),
            "outliers": self.outliers,
            "inputs": self.inputs,
        }


def check_tool_length(result: PivotResult, units: str, path: str | os.PathLike[str]) -> None:
    """Refuse a tip farther from the tool's origin than a tool can be, or nearer
    (:data:`~brachycal.validate.TOOL_LENGTH_M_RANGE`): poses in the other unit than ``units``."""
    scale = 1.0 if units == "m" else 1e-3
    length_m = float(np.linalg.norm(result.p_marker_tip)) * scale
    low, high = TOOL_LENGTH_M_RANGE
    if low <= length_m <= high:
        return
    other = "mm" if units == "m" else "m"
    shown = length_m / scale
    bound = f"longer than {high / scale:g}" if length_m > high else f"shorter than {low / scale:g}"
    raise InputError(
        f"the tip is {shown:.4g} {units} from the tool's origin, read with --units {units}: no tool is "
        f"{bound} {units}; are the poses in {other}? (--units {other})",
        file=path,
    )


def calibrate_pivot_files(path: str | os.PathLike[str], method: str = "algebraic", units: str = "m") -> PivotFileResult:
    """Pivot calibration of the pose list at ``path`` with ``method`` (:data:`PIVOT_METHODS`).

    Args:
        path: CSV pose list (``[key,]m00,…,m33``; :func:`~brachycal.data.pose_list.read_pose_list`).
        method: ``"algebraic"`` (linear least squares) or ``"robust"`` (soft-L1 loss, flags outliers).
        units: the units of the poses' translations, recorded with the result (nothing is converted).

    Raises:
        InputError: the file cannot be read, a matrix is not rigid, an unknown method or unit.
        DegenerateDataError: the poses cannot determine the tip (naming the file).
    """
    if method not in PIVOT_METHODS:
        raise InputError(f"unknown pivot method {method!r}; choose from {', '.join(PIVOT_METHODS)}")
    if units not in UNITS:
        raise InputError(f"units must be one of {', '.join(UNITS)}, got {units!r}")
    names, T, _ = read_pose_list(path)
    try:
        result = PIVOT_METHODS[method](T)
    except InputError as exc:  # too few poses, or poses that cannot determine the tip: name their file
        if exc.file is not None:
            raise
        kind = DegenerateDataError if isinstance(exc, DegenerateDataError) else InputError
        raise kind(exc.problem, file=path) from None
    check_tool_length(result, units, path)
    return PivotFileResult(result, names, units, {Path(path).name: sha256_file(path)})


def write_pivot(calibration: PivotFileResult, path: str | os.PathLike[str], *, force: bool = False) -> Path:
    """Write ``calibration`` as ``brachycal-pivot/1`` JSON, all or nothing (never NaN).

    Raises:
        OutputError: the file exists (without ``force``), cannot be written, or holds a NaN.
    """
    return write_json(path, calibration.to_json(), force=force)


@dataclass(frozen=True)
class PivotFile:
    """What a ``brachycal-pivot/1`` file holds (lengths in ``units``).

    Attributes:
        p_tool_tip: ``(3,)`` the tip in the tool's frame.
        p_reference_pivot: ``(3,)`` the pivot point in the reference frame.
        units: ``"m"`` or ``"mm"``.
        raw: the whole payload (residuals, predicted SDs, outliers, input hashes).
    """

    p_tool_tip: FloatArray
    p_reference_pivot: FloatArray
    units: str
    raw: dict


def pivot_document(raw: Any, where: Where) -> None:
    """The schema of a ``brachycal-pivot/1`` document (:mod:`brachycal.data.json_schema`): ``units``
    ``m`` or ``mm``, the tip and the pivot three numbers within
    :data:`~brachycal.data.json_schema.MAX_TRANSLATION_M` of their frames, and the tip as far from
    the tool's origin as a tool is long (:data:`~brachycal.validate.TOOL_LENGTH_M_RANGE`: a pivot
    written in the other unit than its ``units`` say is refused)."""
    Obj(required={"units": one_of(UNITS)})(raw, where)
    Obj(required={"tip_in_tool": array(number(), length=3), "pivot_in_reference": array(number(), length=3)})(
        raw, where
    )
    scale = 1.0 if raw["units"] == "m" else 1e-3  # metres per unit
    length_m = float(np.linalg.norm(raw["tip_in_tool"])) * scale
    low, high = TOOL_LENGTH_M_RANGE
    if not low <= length_m <= high:
        other = "mm" if raw["units"] == "m" else "m"
        raise where.at("tip_in_tool").refuse(
            f"the tip is {length_m / scale:.4g} {raw['units']} from the tool's origin: no tool is shorter than "
            f"{low / scale:g} or longer than {high / scale:g} {raw['units']}; is it in {other}?"
        )
    reach = MAX_TRANSLATION_M / scale
    array(number(-reach, reach, raw["units"]), length=3)(raw["pivot_in_reference"], where.at("pivot_in_reference"))


def read_pivot(path: str | os.PathLike[str]) -> PivotFile:
    """Read a ``brachycal-pivot/1`` file back.

    Raises:
        InputError: not readable JSON, another format, or a value :func:`pivot_document` refuses
            (naming the file and the key).
    """
    path = Path(path)
    raw = read_document(path, FORMAT, pivot_document)

    def point(key: str) -> FloatArray:
        return np.array(raw[key], dtype=float)

    return PivotFile(point("tip_in_tool"), point("pivot_in_reference"), raw["units"], raw)


#: Former names, given for one release with a DeprecationWarning.
if not TYPE_CHECKING:  # type checkers see only the new names
    __getattr__ = renamed(
        __name__,
        {"PivotCalibration": "PivotFileResult", "StoredPivot": "PivotFile", "pivot_from_file": "calibrate_pivot_files"},
    )
