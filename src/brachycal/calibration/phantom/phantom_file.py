"""Files of the phantom methods: the phantom's geometry (TOML), the observations (CSV), the result (JSON).

Geometry ``brachycal-phantom/1`` in millimetres in the phantom frame; tracker readings in metres
with quaternions in ROS order (x, y, z, w).

Design: ``docs/design/phantoms.md``, "Phantom files".
"""

from __future__ import annotations

import os
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from brachycal.data.formats.csv_log import read_table, to_float
from brachycal.errors import InputError
from brachycal.inputs import MAX_DOCUMENT_BYTES, read_input_text
from brachycal.io import atomic_open
from brachycal.se3 import FloatArray, inverse, make_transform
from brachycal.validate import MAX_IMAGE_PX, MAX_POSITION_M, check_positions, check_transform

FORMAT = "brachycal-phantom/1"
RESULT_FORMAT = "brachycal-phantom-result/1"
KINDS = ("multi-wedge", "wire")
POSE_COLUMNS = {
    body: [f"{body}_{c}" for c in ("x", "y", "z", "qx", "qy", "qz", "qw")] for body in ("probe", "reference")
}
PIXEL_COLUMNS = {"multi-wedge": ["u0_px", "v0_px", "u1_px", "v1_px"], "wire": ["u_px", "v_px"]}
#: Largest departure of a quaternion's norm from 1 that is read as rounding (9 decimals or fewer).
QUATERNION_TOLERANCE = 1e-5
MM = 1e-3


@dataclass(frozen=True)
class PhantomGeometry:
    """What both phantom kinds share: name, registration landmarks and the reference-body pose.

    Attributes:
        name: readable name. source: the file read (or None).
        landmarks_m: ``(L, 3)`` registration divots, metres, phantom frame (``(0, 3)`` without).
        T_reference_phantom: ``(4, 4)`` the phantom frame in its reference body's, metres, or None
            when the file does not give it (a geometry only: the lab's registration is not known).
    """

    name: str
    source: str | None
    landmarks_m: FloatArray
    T_reference_phantom: FloatArray | None

    def registration(self) -> FloatArray:
        """``T_reference_phantom (4, 4)``, metres; refused in one line when the geometry has none.

        No default: an identity standing in for a missing registration gives a calibration that is
        wrong by the phantom's whole pose, with only a large residual to say so.
        """
        if self.T_reference_phantom is None:
            raise InputError(
                "no T_reference_phantom_mm: the phantom's pose on its reference body (its registration, "
                "PLUS's Phantom->Reference) is needed to use the tracker readings",
                file=self.source,
            )
        return self.T_reference_phantom


def load_toml(path: str | os.PathLike[str], kind: str) -> tuple[dict, PhantomGeometry]:
    """The TOML table of a geometry file of ``kind`` and its shared part.

    Raises:
        InputError: unreadable file, wrong format or kind, bad landmarks or transform (one line).
    """
    path = Path(path)
    try:
        data = tomllib.loads(read_input_text(path, max_bytes=MAX_DOCUMENT_BYTES))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError, RecursionError) as exc:
        raise InputError(f"not a readable TOML file ({exc})", file=path) from None
    if data.get("format") != FORMAT:
        raise InputError(f"format must be {FORMAT!r}, got {data.get('format')!r}", file=path)
    if data.get("kind") != kind:
        raise InputError(
            f"is a {data.get('kind')!r} phantom, not a {kind!r} one (see its 'kind' key; kinds: {', '.join(KINDS)})",
            file=path,
        )
    name = str(data.get("name", path.stem))
    landmarks = vector_list(data.get("landmarks_mm", []), "landmarks_mm", path).reshape(-1, 3) * MM
    T = None
    if "T_reference_phantom_mm" in data:
        try:
            T = np.array(data["T_reference_phantom_mm"], dtype=float)
        except (TypeError, ValueError):
            raise InputError("T_reference_phantom_mm must be a 4x4 matrix of numbers", file=path) from None
        T = check_transform(T, "T_reference_phantom_mm", file=path).copy()
        check_positions(T[:3, 3], "T_reference_phantom_mm translation", limit=MAX_POSITION_M / MM, unit="mm", file=path)
        T[:3, 3] *= MM
    return data, PhantomGeometry(name, str(path), landmarks, T)


def vector(value: object, name: str, path: Path | None, limit: float | None = MAX_POSITION_M / MM) -> FloatArray:
    """``(3,)`` finite numbers of a TOML value, each within ``±limit`` (default: a position in
    millimetres, :data:`~brachycal.validate.MAX_POSITION_M`), refused in one line otherwise."""
    try:
        v = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be three numbers, got {value!r}", file=path) from None
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise InputError(f"{name} must be three finite numbers, got {value!r}", file=path)
    if limit is not None:
        check_positions(v, name, limit=limit, unit="mm", file=path)
    return v


def vector_list(value: object, name: str, path: Path | None) -> FloatArray:
    """``(L, 3)`` finite numbers of a TOML list of triples."""
    if not isinstance(value, list):
        raise InputError(f"{name} must be a list of [x, y, z] triples", file=path)
    return np.array([vector(v, f"{name}[{k}]", path) for k, v in enumerate(value)]).reshape(-1, 3)


def entries(data: dict, key: str, path: Path | None) -> list[dict]:
    """The ``[[key]]`` tables of a TOML file, each with a unique non-empty ``name``."""
    tables = data.get(key, [])
    if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
        raise InputError(f"{key!r} must be an array of tables ([[{key}]])", file=path)
    return tables


def unique_name(table: dict, what: str, seen: set[str], path: Path | None) -> str:
    name = table.get("name")
    if not isinstance(name, str) or not name.strip():
        raise InputError(f"a {what} has no name", file=path)
    if name in seen:
        raise InputError(f"{what} name {name!r} appears twice", file=path)
    seen.add(name)
    return name


@dataclass(frozen=True)
class PhantomObservations:
    """Tracked frames and the features segmented in them (metres; pixels).

    Attributes:
        frames: ``(F,)`` frame names in the order of first appearance.
        T_tracker_probe: ``(F, 4, 4)`` the probe's marker body in the tracker frame.
        T_tracker_reference: ``(F, 4, 4)`` the phantom's reference body in the tracker frame.
        frame: ``(K,)`` frame index of each observation. feature: ``(K,)`` feature names.
        uv_px: ``(K, P, 2)`` the observation's image points (P = 2 line ends, or 1 wire point).
        rows: ``(K,)`` file rows (header = 1). source: the file.
    """

    frames: list[str]
    T_tracker_probe: FloatArray
    T_tracker_reference: FloatArray
    frame: np.ndarray
    feature: list[str]
    uv_px: FloatArray
    rows: list[int]
    source: str | None = None

    def T_phantom_marker(self, T_reference_phantom: FloatArray) -> FloatArray:
        """``(F, 4, 4)`` the probe's marker body in the phantom frame, per frame."""
        return inverse(self.T_tracker_reference @ T_reference_phantom) @ self.T_tracker_probe


def _check_quaternions(path: Path, quaternions: FloatArray, rows: list[int], body: str) -> None:
    """Refuse a quaternion ``(K, 4)`` that is not a unit one (beyond rounding), naming its row."""
    norms = np.linalg.norm(quaternions, axis=1)
    bad = np.flatnonzero(np.abs(norms - 1.0) > QUATERNION_TOLERANCE)
    if bad.size:
        k = int(bad[0])
        raise InputError(
            f"the {body} quaternion has norm {norms[k]:.6g}, not 1 (ROS order qx, qy, qz, qw)",
            file=path,
            row=rows[k],
            column=f"{body}_qw",
        )


def _poses(numbers: FloatArray) -> FloatArray:
    """``(K, 4, 4)`` from checked ``x, y, z, qx, qy, qz, qw`` rows ``(K, 7)``."""
    from scipy.spatial.transform import Rotation  # lazy: start-up (scipy)

    return make_transform(Rotation.from_quat(numbers[:, 3:]).as_matrix(), numbers[:, :3])


def read_observations(path: str | os.PathLike[str], kind: str, features: list[str]) -> PhantomObservations:
    """Read an observations CSV of ``kind`` whose features must be among ``features`` (module docstring).

    Raises:
        InputError: a missing column, a non-number or non-finite field, an unknown feature, a
            feature twice in one frame, a frame whose rows disagree on the tracker readings, a
            quaternion that is not a unit one — naming the file, row and column.
    """
    path = Path(path)
    pixel_columns = PIXEL_COLUMNS[kind]
    required = ["frame", "feature", *POSE_COLUMNS["probe"], *POSE_COLUMNS["reference"], *pixel_columns]
    header, rows, records = read_table(path, required)
    if not records:
        raise InputError("has no observations (only a header)", file=path)
    numeric = [*POSE_COLUMNS["probe"], *POSE_COLUMNS["reference"], *pixel_columns]
    numbers = to_float(path, header, rows, records, numeric)
    bad = np.argwhere(~np.isfinite(numbers))
    if bad.size:
        k, c = (int(i) for i in bad[0])
        raise InputError("is not a finite number", file=path, row=rows[k], column=numeric[c])
    for body in ("probe", "reference"):  # metres: a reading in millimetres is far beyond any tracker's range
        position = POSE_COLUMNS[body][:3]
        check_positions(
            numbers[:, [numeric.index(c) for c in position]],
            f"the {body} position (metres)",
            limit=MAX_POSITION_M,
            unit="m",
            file=path,
            rows=rows,
            columns=position,
        )
    check_positions(
        numbers[:, [numeric.index(c) for c in pixel_columns]],
        "",
        limit=MAX_IMAGE_PX,
        unit="px",
        file=path,
        rows=rows,
        columns=pixel_columns,
    )
    names = [fields[header.index("frame")].strip() for fields in records]
    feature = [fields[header.index("feature")].strip() for fields in records]
    known = set(features)
    frames: list[str] = []
    index: dict[str, int] = {}
    seen: set[tuple[str, str]] = set()
    frame_of = np.empty(len(records), dtype=int)
    for k, (frame, name) in enumerate(zip(names, feature, strict=True)):
        if not frame:
            raise InputError("has an empty frame name", file=path, row=rows[k], column="frame")
        if name not in known:
            raise InputError(
                f"feature {name!r} is not a {'face' if kind == 'multi-wedge' else 'wire'} of the phantom "
                f"(it has {', '.join(features[:6])}{', ...' if len(features) > 6 else ''})",
                file=path,
                row=rows[k],
                column="feature",
            )
        if (frame, name) in seen:
            raise InputError(f"feature {name!r} appears twice in frame {frame!r}", file=path, row=rows[k])
        seen.add((frame, name))
        if frame not in index:
            index[frame] = len(frames)
            frames.append(frame)
        frame_of[k] = index[frame]
    first = np.array([names.index(f) for f in frames])
    pose_numbers = numbers[:, :14]
    for body, columns in (("probe", slice(3, 7)), ("reference", slice(10, 14))):
        _check_quaternions(path, pose_numbers[:, columns], rows, body)
    disagree = np.flatnonzero(np.any(np.abs(pose_numbers - pose_numbers[first[frame_of]]) > 0.0, axis=1))
    if disagree.size:
        k = int(disagree[0])
        raise InputError(
            f"the tracker readings differ from those of frame {names[k]!r}'s first row (one reading per frame)",
            file=path,
            row=rows[k],
        )
    probe = _poses(pose_numbers[first, :7])
    reference = _poses(pose_numbers[first, 7:])
    uv = numbers[:, 14:].reshape(len(records), -1, 2)
    return PhantomObservations(frames, probe, reference, frame_of, feature, uv, rows, str(path))


def write_observations(
    path: str | os.PathLike[str], kind: str, observations: PhantomObservations, *, force: bool = False
) -> Path:
    """Write observations in the CSV format above (positions 9 decimals, quaternions 12, pixels 6)."""
    from scipy.spatial.transform import Rotation  # lazy: start-up (scipy)

    def pose(T: FloatArray) -> list[str]:
        q = Rotation.from_matrix(T[:3, :3]).as_quat(canonical=True)
        return [f"{x:.9f}" for x in T[:3, 3]] + [f"{x:.12f}" for x in q]

    header = ["frame", "feature", *POSE_COLUMNS["probe"], *POSE_COLUMNS["reference"], *PIXEL_COLUMNS[kind]]
    with atomic_open(path, force=force) as handle:
        handle.write(",".join(header) + "\n")
        for k, name in enumerate(observations.feature):
            f = observations.frame[k]
            fields = [observations.frames[f], name]
            fields += pose(observations.T_tracker_probe[f]) + pose(observations.T_tracker_reference[f])
            fields += [f"{x:.6f}" for x in observations.uv_px[k].ravel()]
            handle.write(",".join(fields) + "\n")
    return Path(path)


def result_payload(calibration, inputs: dict[str, str]) -> dict:
    """The ``brachycal-phantom-result/1`` JSON of a
    :class:`~brachycal.calibration.phantom.features.PhantomResult`."""
    return {
        "format": RESULT_FORMAT,
        "method": calibration.method,
        "transforms": {"Marker_T_I": np.asarray(calibration.T_marker_image).tolist()},
        "spacing_m": np.asarray(calibration.spacing_m).tolist(),
        "frames": calibration.frames,
        "observations": calibration.observations,
        "residual_rms_mm": float(np.sqrt(np.mean(calibration.residuals_m**2)) * 1e3),
        "noise_sd_mm": calibration.noise_sd_m * 1e3,
        "predicted_sd_at_reach_mm": {
            "segmentation_only": calibration.reach_sd_m * 1e3,
            "with_fit_residual": calibration.reach_sd_fit_m * 1e3,
        },
        "inputs": inputs,
    }
