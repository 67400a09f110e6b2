"""Calibration result, format ``brachycal-result/1`` (a JSON file; ``docs/conventions.md``).

Transforms are 4×4 row-major lists in metres. Besides the keys of the conventions
(``transforms``, ``mechanical``, ``loocv``, ``inputs``), the file carries the pixel spacing each
registration method goes with (``spacing_mm``), the reference tips, fit residuals, the samples'
names, the tool-axes angles, and the software versions that produced it.

``refused`` (added the same way; only in a result where a method refused) maps each registration
method the samples could not determine to the reason, one line: that method has no transform, and
asking for it (:meth:`ResultFile.method`) is refused with that reason.

``robot`` (a key added with robot descriptions; the format stays ``brachycal-result/1``, as the
conventions allow added keys) records which robot the result was calibrated with: the
description's ``name`` (``--robot``), its file and SHA-256, the SHA-256 of the URDF text the model
was built from and the configuration's joint names. :meth:`ResultFile.software_robot`
refuses a robot of another name or other joints (its flanges are other links: the transforms would
be applied to the wrong arm), and warns when the description file changed since. Files written
before it (no ``robot`` key; ``robot_model`` only) are read as they are: the SDA10F was then the
only robot, and nothing is checked.

A URDF written by ``brachycal export`` records the result it came from (the file's SHA-256) and
which of its corrections the joints carry (:meth:`ResultFile.export_record`);
:meth:`ResultFile.software_robot` reads that record, so that corrections are applied once
even for files that store joint offsets without the corrected joint origins.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from brachycal._lazy import renamed
from brachycal._version import __version__
from brachycal.calibration.result import Calibration, ImageCalibration, Provenance, best_method
from brachycal.calibration.sequential.image_to_probe import METHODS
from brachycal.calibration.sequential.method import SequentialResult
from brachycal.calibration.session.chain_report import chain_json
from brachycal.calibration.session.result_schema import FORMAT, validate_result_document
from brachycal.data.json_files import parse_json, read_json_bytes
from brachycal.errors import BrachycalWarning, InputError
from brachycal.io import sha256_bytes, sha256_file, write_json
from brachycal.model.description import BUNDLED_ROBOTS
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray


@dataclass(frozen=True)
class RobotRecord:
    """Which robot a result was calibrated with (the result file's ``robot`` block).

    Attributes:
        name: the description's name (``--robot NAME``).
        description: the description file it was read from.
        description_sha256: SHA-256 of that file's bytes ("" if it could not be read).
        urdf_sha256: SHA-256 of the URDF text the model was built from (tool frames included).
        joint_names: the configuration's columns, in order.
    """

    name: str
    description: str
    description_sha256: str
    urdf_sha256: str
    joint_names: tuple[str, ...]

    @classmethod
    def of(cls, robot: Robot) -> RobotRecord:
        """The record of ``robot`` (its rig: :attr:`Robot.rig`)."""
        rig = robot.rig
        try:
            description_sha256 = sha256_file(rig.source)
        except OSError:  # a rig whose file is gone: the name and the URDF still say which robot
            description_sha256 = ""
        return cls(rig.name, str(rig.source), description_sha256, sha256_bytes(robot.urdf_xml), robot.joint_names)

    def as_json(self) -> dict[str, object]:
        return {
            "name": self.name,
            "description": self.description,
            "description_sha256": self.description_sha256,
            "urdf_sha256": self.urdf_sha256,
            "joint_names": list(self.joint_names),
        }

    @property
    def option(self) -> str:
        """The ``--robot`` argument that loads it again: the bundled name (a description read from
        brachycal's ``robots/<name>.toml``, wherever brachycal was installed), else the description file."""
        bundled = self.name in BUNDLED_ROBOTS and Path(self.description).parts[-2:] == ("robots", f"{self.name}.toml")
        return self.name if bundled else self.description


def to_json(
    result: SequentialResult,
    *,
    robot_source: str = "",
    robot_sha256: str = "",
    chain=None,
    robot: Robot | None = None,
) -> dict:
    """The result as a JSON-ready dict.

    With ``robot`` (the model it was calibrated with), ``robot_model`` is its URDF's source and
    SHA-256 (``robot_source`` and ``robot_sha256`` are then ignored) and ``robot`` its
    :class:`RobotRecord`.

    With ``chain`` (a :class:`~brachycal.calibration.session.chain_report.ChainResult`), the transforms
    are the whole-chain method's (``Ptip_T_I`` and ``spacing_mm`` under ``"chain"``), its section
    ``chain`` is added, and the sequential method's transforms and figures stay under
    ``sequential`` for comparison (they go with its own ``EL_T_Ptip``).
    """
    import pinocchio  # lazy: start-up (pinocchio)

    def tool(calibration) -> dict:
        out = calibration.validation.as_dict(with_errors=True)
        out["axes_angle_deg"] = calibration.rotation.axes_angle_deg
        # Predicted uncertainties (conditioning checks): tip from the trials' spread, rotation
        # and axes angle from the moves' lengths and the stated positioning noise.
        if calibration.tip is not None:
            out["predicted_tip_sd_mm"] = calibration.tip.sd_m * 1e3
        out["predicted_rotation_sd_deg"] = calibration.rotation.rotation_sd_deg
        out["axes_angle_sd_deg"] = calibration.rotation.axes_angle_sd_deg
        return out

    record = None
    if robot is not None:
        record = RobotRecord.of(robot)
        robot_source, robot_sha256 = robot.source, record.urdf_sha256
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
        "reference_tips_sd_mm": {k: tip.sd_m * 1e3 for k, tip in result.reference_tips.items()},
        "predicted_uncertainty": {m: c.uncertainty.as_dict() for m, c in result.image.items() if c.uncertainty},
        "samples": result.sample_ids,
        **({"image": {"size_px": list(result.image_size_px)}} if result.image_size_px else {}),
        "inputs": result.inputs,
        "robot_model": {"urdf": robot_source, "sha256": robot_sha256},
        **({"robot": record.as_json()} if record is not None else {}),
        **({"refused": dict(result.refused)} if result.refused else {}),
        "software": {"brachycal": __version__, "pinocchio": pinocchio.__version__, "numpy": np.__version__},
    }
    if chain is None:
        return payload

    sequential = {
        k: payload.pop(k) for k in ("transforms", "spacing_mm", "loocv", "fit_residuals", "predicted_uncertainty")
    }
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
    result: SequentialResult,
    path: str | os.PathLike[str],
    *,
    force: bool = False,
    robot_source: str = "",
    robot_sha256: str = "",
    chain=None,
    robot: Robot | None = None,
) -> Path:
    """Write the result atomically; never replaces an existing file unless ``force``.

    ``robot``: the model it was calibrated with, recorded (:func:`to_json`); give it, so that
    ``locate`` and ``export`` can refuse another robot.

    Raises:
        OutputError: the file exists (without ``force``), cannot be written, or a value is NaN or
            infinite (the error names its key; JSON has no NaN).
    """
    payload = to_json(result, robot_source=robot_source, robot_sha256=robot_sha256, chain=chain, robot=robot)
    return write_json(path, payload, force=force)


@dataclass(frozen=True, repr=False)
class ResultFile:
    """What targeting needs from a result file."""

    T_ER_Ntip: FloatArray
    T_EL_Ptip: FloatArray
    image: dict[str, ImageCalibration]
    raw: dict
    joint_offsets_rad: dict[str, float] = field(default_factory=dict)
    #: ``(width, height)`` of the calibrated images, pixels (``image.size_px``); None in files
    #: written before it was stored.
    image_size_px: tuple[int, int] | None = None
    #: ``{joint: (urdf (4, 4), corrected (4, 4))}``: the joint origins of the URDF the result was
    #: calibrated with and of the robot it corrected them to (empty: the result corrects nothing).
    joint_origins: dict[str, tuple[FloatArray, FloatArray]] = field(default_factory=dict)
    source: str = ""
    #: The robot it was calibrated with (the ``robot`` block); None in files written before it.
    robot: RobotRecord | None = None
    #: SHA-256 of the result file's bytes ("" for a result not read from a file).
    sha256: str = ""
    #: Method → why it was refused at calibration (the ``refused`` block; empty: none was).
    refused: dict[str, str] = field(default_factory=dict)

    def __repr__(self) -> str:
        """A few lines: the file, its methods (the best marked) and what the best one is."""
        best = self.best_method() if self.image else None
        methods = ", ".join(m + (" (best)" if m == best else "") for m in self.image)
        lines = [f"ResultFile {self.source or '(not read from a file)'}: image methods {methods or 'none'}"]
        lines += [f"  refused {m}: {why}" for m, why in self.refused.items()]
        if best is not None:
            lines += ["  " + line for line in repr(self.calibration()).splitlines()]
        return "\n".join(lines)

    def best_method(self) -> str:
        """The image calibration to use when none is asked for (``locate``, ``export``, ``view``).

        The whole chain's if the result has it (``chain+robot``, then ``chain``): it is solved over
        all the data with its own uncertainty. Otherwise the registration with the lowest
        leave-one-out RMSE in the result (``loocv.<method>.rmse_mm``); RMSEs within 1e-9 relative
        of each other are ties (Kabsch and Horn solve the same least squares and differ only in
        rounding), broken by Table II's order (icp, kabsch, horn, similarity, scaled_uv); methods
        without a leave-one-out RMSE come last. A method refused at calibration (:attr:`refused`)
        has no transform, so it is never chosen.
        """
        loocv = self.raw.get("loocv", {}) if isinstance(self.raw.get("loocv"), dict) else {}
        rmse = {m: e.get("rmse_mm") for m, e in loocv.items() if isinstance(e, dict)}
        order = list(dict.fromkeys(m for m in (*METHODS, *self.image) if m in self.image))
        return best_method(order, rmse)

    def calibration(self, method: str | None = None) -> Calibration:
        """The :class:`~brachycal.calibration.result.Calibration` of image method ``method``
        (:meth:`best_method` for None), with the result's robot corrections and provenance.

        Raises:
            InputError: as :meth:`method` (no such method, or refused at calibration).
        """
        chosen = self.method(method)
        inputs = self.raw.get("inputs", {})
        return Calibration(
            T_ER_Ntip=self.T_ER_Ntip,
            T_EL_Ptip=self.T_EL_Ptip,
            image=self.image[chosen],
            joint_offsets_rad=self.joint_offsets_rad,
            joint_origins=self.joint_origins,
            image_size_px=self.image_size_px,
            provenance=Provenance(
                source=self.source,
                sha256=self.sha256,
                inputs={str(k): str(v) for k, v in inputs.items()} if isinstance(inputs, dict) else {},
            ),
        )

    def method(self, asked: str | None) -> str:
        """The image calibration ``asked`` for (an option's value), or :meth:`best_method` for None.

        Raises:
            InputError: the result has no such method, or that method was refused at calibration
                (naming the result file, and what it has or why it was refused).
        """
        method = asked or self.best_method()
        if method in self.refused and method not in self.image:
            raise InputError(
                f"method {method!r} was refused when this result was calibrated ({self.refused[method]}); "
                f"choose another (it has {', '.join(self.image)})",
                file=self.source,
                column=f"refused.{method}",
            )
        if method not in self.image:
            raise InputError(f"the result has no method {method!r} (it has {', '.join(self.image)})", file=self.source)
        return method

    def corrections(self) -> list[str]:
        """Which robot corrections the result carries: ``joint_origins`` (identified geometry, or
        joint offsets stored as corrected origins), ``joint_offsets`` (zero offsets); empty: none."""
        out = []
        if self.joint_origins:
            out.append("joint_origins")
        if self.joint_offsets_rad:
            out.append("joint_offsets")
        return out

    def export_record(self, method: str) -> dict[str, str]:
        """The ``<brachycal_export>`` attributes of a URDF written from this result: the result file
        and its SHA-256, the image method, and what the URDF carries (``tool_frames`` always, and
        :meth:`corrections`)."""
        return {
            "result": Path(self.source).name,
            "result_sha256": self.sha256,
            "method": method,
            "carries": " ".join(["tool_frames", *self.corrections()]),
            "brachycal": __version__,
        }

    def check_robot(self, robot: Robot) -> None:
        """Refuse a robot other than the one the result was calibrated with (nothing to check for
        files without a ``robot`` block).

        Raises:
            InputError: another description name, or other joints (one line naming the result
                file and the ``--robot`` that fits).

        Warns:
            BrachycalWarning: the same robot, but its description file changed since calibration.
        """
        record = self.robot
        if record is None:
            return
        rig = robot.rig
        if rig.name != record.name:
            raise InputError(
                f"calibrated on robot {record.name!r}, not {rig.name!r}: pass --robot {record.option}",
                file=self.source,
                column="robot.name",
            )
        if tuple(robot.joint_names) != record.joint_names:
            missing = [n for n in record.joint_names if n not in robot.joint_names]
            extra = [n for n in robot.joint_names if n not in record.joint_names]
            what = (
                f"it has no {', '.join(missing[:3])}"
                if missing
                else f"it also has {', '.join(extra[:3])}"
                if extra
                else "its joints in another order"
            )
            raise InputError(
                f"robot {rig.name!r} has other joints than the one this result was calibrated with "
                f"({what}): pass --robot {record.option}",
                file=self.source,
                column="robot.joint_names",
            )
        if record.description_sha256:
            try:
                now = sha256_file(rig.source)
            except OSError:
                return
            if now != record.description_sha256:
                warnings.warn(
                    f"{self.source}: robot description {rig.source} has changed since this result was "
                    "calibrated with it (its SHA-256 differs): if its kinematics changed, calibrate again",
                    BrachycalWarning,
                    stacklevel=2,
                )

    def software_robot(self, robot: Robot) -> Robot:
        """The robot model to compute and command with: ``robot`` with the result's corrections
        (identified geometry or joint offsets), applied exactly once.

        A robot whose joint origins already are the corrected ones (the URDF ``brachycal export``
        wrote) is returned as it is; one whose origins are the calibrated URDF's is corrected. For
        a result that stores no corrected origins (no corrections, or joint offsets in files
        written before the origins were stored), the URDF's ``<brachycal_export>`` records decide:
        a URDF exported from this very result (same SHA-256) already carries its offsets and is
        returned as it is; one exported from another result that corrected the robot is refused,
        unless this result was calibrated on that very URDF (the result's ``robot.urdf_sha256``).

        Raises:
            InputError: ``robot`` is not the robot the result was calibrated with
                (:meth:`check_robot`); the result corrects the robot and ``robot``'s joint origins
                are neither (another calibration's corrections: they would be mixed); or the result
                stores no corrected origins and ``robot`` is a URDF exported from another result
                that corrected the robot, which this result was not calibrated on.
        """
        self.check_robot(robot)
        if not self.joint_origins:
            records = robot.export_records
            if self.joint_offsets_rad and any(
                r.get("result_sha256") == self.sha256 and _carries_joints(r) for r in records
            ):
                return robot  # exported from this result: its offsets are in the joints already
            others = [r for r in records if _carries_joints(r) and r.get("result_sha256") != self.sha256]
            calibrated_on_it = self.robot is not None and self.robot.urdf_sha256 == sha256_bytes(robot.urdf_xml)
            if others and not calibrated_on_it:
                why = (
                    "this result's joint offsets would be added to those corrections"
                    if self.joint_offsets_rad
                    else "this result was not calibrated with those corrections"
                )
                raise InputError(
                    f"the robot model is a URDF exported from another result ({others[-1].get('result', '?')}) "
                    f"that corrected the robot: {why}; use the URDF this result was calibrated with",
                    file=self.source,
                )
            return robot.with_joint_offsets(self.joint_offsets_rad) if self.joint_offsets_rad else robot
        names = [name for name in self.joint_origins if name in robot.joint_names]
        if len(names) != len(self.joint_origins):
            missing = sorted(set(self.joint_origins) - set(names))[:3]
            raise InputError(
                f"the robot model has no joint(s) {', '.join(missing)} that this result corrects", file=self.source
            )
        here = {name: robot.joint_origin(name) for name in names}
        if all(_same_origin(here[n], self.joint_origins[n][1]) for n in names):
            return robot  # already corrected: never apply the corrections twice
        if not all(_same_origin(here[n], self.joint_origins[n][0]) for n in names):
            raise InputError(
                "the robot model's joint origins are neither those of the URDF this result was calibrated with "
                "nor its corrected ones: use that URDF (or the one 'brachycal export' wrote from this result)",
                file=self.source,
            )
        return robot.with_joint_origins({n: self.joint_origins[n][1] for n in names})


def _carries_joints(record: dict[str, str]) -> bool:
    """Whether an export record says its URDF's joints carry robot corrections."""
    return bool({"joint_origins", "joint_offsets"} & set(record.get("carries", "").split()))


#: Two joint origins are the same when no entry differs by more than this (metres, and unitless
#: rotation entries): far above the round trip through a URDF's text (~1e-15), far below any
#: correction worth making (a robot correction of 1e-9 m or 1e-9 rad changes nothing measurable).
ORIGIN_TOLERANCE = 1e-9


def _same_origin(a: FloatArray, b: FloatArray) -> bool:
    return bool(np.max(np.abs(a - b)) <= ORIGIN_TOLERANCE)


def _matrix(value: object) -> FloatArray:
    """A ``(4, 4)`` transform of a validated document (:mod:`~brachycal.calibration.session.result_schema`)."""
    return np.array(value, dtype=float)


def read_result(path: str | os.PathLike[str]) -> ResultFile:
    """Read a result file back; refuses anything that is not a valid ``brachycal-result/1``.

    The whole document is checked first (:func:`~brachycal.calibration.session.result_schema.validate_result_document`:
    types, shapes, finite numbers, physical ranges, proper rotations), before any of it is used.

    Raises:
        InputError: the file cannot be read, is not bounded JSON (:func:`~brachycal.data.json_files.parse_json`),
            or its first problem, naming the file and the key's place in the document.
    """
    path = Path(path)
    data = read_json_bytes(path)  # validated and hashed: the same bytes
    raw = validate_result_document(parse_json(data, path), path)
    transforms = raw["transforms"]
    image = {
        method: ImageCalibration(method, _matrix(T), np.array(raw["spacing_mm"][method], dtype=float) * 1e-3)
        for method, T in transforms["Ptip_T_I"].items()
    }
    chain = raw.get("chain", {})
    size = raw.get("image", {}).get("size_px")
    return ResultFile(
        T_ER_Ntip=_matrix(transforms["ER_T_Ntip"]),
        T_EL_Ptip=_matrix(transforms["EL_T_Ptip"]),
        image=image,
        raw=raw,
        joint_offsets_rad={k: float(v) for k, v in chain.get("joint_offsets_rad", {}).items()},
        image_size_px=None if size is None else (int(size[0]), int(size[1])),
        joint_origins={
            name: (_matrix(pair["urdf"]), _matrix(pair["corrected"]))
            for name, pair in chain.get("robot_joint_origins", {}).items()
        },
        source=str(path),
        robot=_robot_record(raw),
        sha256=sha256_bytes(data),
        refused=_refused(raw, path, image),
    )


def _refused(raw: dict, path: Path, image: dict[str, ImageCalibration]) -> dict[str, str]:
    """The ``refused`` block of a validated document (a map of strings, by the schema): registration
    method → its reason (empty if the file has none)."""
    block = raw.get("refused", {})
    for method, reason in block.items():
        if method not in METHODS:
            raise InputError(f"unknown method {method!r}", file=path, column="refused")
        if not reason.strip():
            raise InputError("must be the reason, a non-empty string", file=path, column=f"refused.{method}")
        if method in image:
            raise InputError(
                "a method cannot both be refused and have a transform", file=path, column=f"refused.{method}"
            )
    return {str(m): str(r) for m, r in block.items()}


def _robot_record(raw: dict) -> RobotRecord | None:
    """The ``robot`` block of a validated document, or None if the file has none (written before
    robot descriptions)."""
    if "robot" not in raw:
        return None
    block = raw["robot"]
    return RobotRecord(
        name=block["name"],
        description=block["description"],
        description_sha256=block["description_sha256"],
        urdf_sha256=block["urdf_sha256"],
        joint_names=tuple(block["joint_names"]),
    )


#: Former names, given for one release with a DeprecationWarning.
if not TYPE_CHECKING:  # type checkers see only the new names
    __getattr__ = renamed(__name__, {"StoredCalibration": "ResultFile"})
