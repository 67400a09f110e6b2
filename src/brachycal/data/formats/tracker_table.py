"""Tracker measurement tables: one row per robot posture, its joint values and where an external
tracker saw a marker on the arm (3-D position, optionally its orientation too).

The columns are named by a small spec (:class:`TrackerColumns`), given in a TOML file
(:func:`read_tracker_columns`) so that any tracker's export can be read without reformatting::

    format = "brachycal-tracker-columns/1"
    joints = ["shoulder_pan_joint", "shoulder_lift_joint"]  # columns named as the robot's joints
    [position]
    columns = ["x", "y", "z"]
    unit = "m"                      # "m" or "mm"
    [orientation]                   # optional: the marker's orientation in the tracker's frame
    columns = ["rx", "ry", "rz"]
    kind = "rotation_vector"        # "rotation_vector", "rpy" or "quaternion_xyzw"
    unit = "rad"                    # "rad" or "deg" (not for quaternions)

Joint values are radians (metres for prismatic joints). ``rpy`` is roll, pitch, yaw about the fixed
x, y, z axes: ``R = Rz(yaw) Ry(pitch) Rx(roll)``. Positions and orientations are the marker's pose
``T_tracker_marker`` in the tracker's own frame, which need not be the robot's.

Units mixed up are refused by magnitude, naming the field: a position beyond ±10 m stated in metres
(millimetres?), every position within ±10 mm stated in millimetres (metres?), a rotation beyond
2π rad stated in radians (degrees?), every angle within ±π stated in degrees while the joints turn
by half a radian or more (radians?), a quaternion not of unit norm.
"""

from __future__ import annotations

import os
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from brachycal.data.formats.csv_log import read_table, to_float
from brachycal.errors import InputError
from brachycal.inputs import MAX_DOCUMENT_BYTES, read_input_text
from brachycal.se3 import FloatArray
from brachycal.validate import MAX_POSITION_M, check_positions

__all__ = [
    "COLUMNS_FORMAT",
    "MIN_TRACKER_ROWS",
    "ORIENTATION_KINDS",
    "TrackerColumns",
    "TrackerTable",
    "read_tracker_columns",
    "read_tracker_table",
]

COLUMNS_FORMAT = "brachycal-tracker-columns/1"
#: Orientation conventions and their column counts.
ORIENTATION_KINDS = {"rotation_vector": 3, "rpy": 3, "quaternion_xyzw": 4}
#: Fewest postures: the tracker's and the marker's frames alone (6 + 3 unknowns) need 3 postures of
#: a 3-D marker, and leave-one-out one more.
MIN_TRACKER_ROWS = 4
#: A table in millimetres whose every coordinate is within this (mm) is in metres: a tracker
#: sees an arm's postures metres from its origin, or at least centimetres apart.
MIN_EXTENT_MM = 10.0
#: Largest rotation angle (radians) or joint value accepted in radians: beyond, degrees.
MAX_ANGLE_RAD = 2 * np.pi
#: Joint travel (radians) past which a marker's orientation must turn by more than a few degrees: a
#: joint turned by 0.5 rad (29°) turns everything beyond it by as much, so orientations stated in
#: degrees that all lie within ±π (at most 6.3° apart) while a joint turns that far are radians.
MIN_JOINT_TURN_RAD = 0.5
#: Largest departure of a quaternion's norm from 1 (trackers write 6 or more digits).
QUATERNION_NORM_TOL = 1e-3


@dataclass(frozen=True)
class TrackerColumns:
    """Which columns of a tracker table hold what (module docstring).

    Attributes:
        joints: columns of joint values, named as the robot's joints (radians; metres for prismatic).
        position: the marker position's three columns (x, y, z in the tracker's frame).
        position_unit: ``"m"`` or ``"mm"``.
        orientation: the orientation's columns (3 or 4 by ``orientation_kind``); empty: none measured.
        orientation_kind: a key of :data:`ORIENTATION_KINDS`, or ``""`` without orientation.
        angle_unit: ``"rad"`` or ``"deg"`` of rotation vectors and roll-pitch-yaw angles.
    """

    joints: tuple[str, ...]
    position: tuple[str, str, str]
    position_unit: str = "m"
    orientation: tuple[str, ...] = ()
    orientation_kind: str = ""
    angle_unit: str = "rad"
    source: str = "<tracker columns>"

    def __post_init__(self) -> None:
        def refuse(message: str, key: str) -> InputError:
            return InputError(message, file=self.source, key=key)

        if not self.joints or not all(isinstance(j, str) and j for j in self.joints):
            raise refuse("expected a non-empty list of joint column names", "joints")
        if len(self.position) != 3 or not all(isinstance(c, str) and c for c in self.position):
            raise refuse("expected three column names (x, y, z)", "position.columns")
        if self.position_unit not in ("m", "mm"):
            raise refuse(f"unit is {self.position_unit!r}; expected 'm' or 'mm'", "position.unit")
        if self.orientation or self.orientation_kind:
            if self.orientation_kind not in ORIENTATION_KINDS:
                raise refuse(
                    f"kind is {self.orientation_kind!r}; expected one of {', '.join(ORIENTATION_KINDS)}",
                    "orientation.kind",
                )
            count = ORIENTATION_KINDS[self.orientation_kind]
            if len(self.orientation) != count or not all(isinstance(c, str) and c for c in self.orientation):
                raise refuse(f"{self.orientation_kind} needs {count} column names", "orientation.columns")
        if self.angle_unit not in ("rad", "deg"):
            raise refuse(f"unit is {self.angle_unit!r}; expected 'rad' or 'deg'", "orientation.unit")
        names = [*self.joints, *self.position, *self.orientation]
        repeated = sorted({n for n in names if names.count(n) > 1})
        if repeated:
            raise refuse(f"column {repeated[0]!r} is named twice", "joints")

    @property
    def six_d(self) -> bool:
        """Whether the orientation is measured too."""
        return bool(self.orientation)

    @classmethod
    def from_mapping(cls, spec: dict[str, object], source: str = "<tracker columns>") -> TrackerColumns:
        """From the TOML layout of the module docstring (a parsed dict).

        Raises:
            InputError: a key is missing or of the wrong type, naming it.
        """
        if spec.get("format") != COLUMNS_FORMAT:
            raise InputError(
                f"format is {spec.get('format')!r}, expected {COLUMNS_FORMAT!r}", file=source, key="format"
            )
        unknown = sorted(set(spec) - {"format", "joints", "position", "orientation"})
        if unknown:
            raise InputError("unknown key", file=source, key=unknown[0])

        def table(key: str, required: bool) -> dict[str, object]:
            value = spec.get(key)
            if value is None and not required:
                return {}
            if not isinstance(value, dict):
                raise InputError("expected a table", file=source, key=key)
            return value

        def names(value: object, key: str) -> tuple[str, ...]:
            if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
                raise InputError("expected a list of column names", file=source, key=key)
            return tuple(value)

        position, orientation = table("position", True), table("orientation", False)
        return cls(
            joints=names(spec.get("joints"), "joints"),
            position=names(position.get("columns"), "position.columns"),  # type: ignore[arg-type]
            position_unit=str(position.get("unit", "")),
            orientation=names(orientation.get("columns"), "orientation.columns") if orientation else (),
            orientation_kind=str(orientation.get("kind", "")) if orientation else "",
            angle_unit=str(orientation.get("unit", "rad")),
            source=source,
        )


def read_tracker_columns(path: str | os.PathLike[str]) -> TrackerColumns:
    """A :class:`TrackerColumns` spec from its TOML file (module docstring).

    Raises:
        InputError: not TOML, or a key missing or wrong, naming it.
    """
    path = Path(path)
    try:
        spec = tomllib.loads(read_input_text(path, max_bytes=MAX_DOCUMENT_BYTES))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError, RecursionError) as exc:
        raise InputError(f"not valid TOML ({exc})", file=path) from None
    return TrackerColumns.from_mapping(spec, str(path))


@dataclass(frozen=True)
class TrackerTable:
    """A tracker table read into SI units.

    Attributes:
        joint_names: the joint columns, in the spec's order.
        Q: ``(N, J)`` joint values (radians; metres for prismatic joints).
        p_tracker_marker: ``(N, 3)`` the marker's position in the tracker's frame (metres).
        R_tracker_marker: ``(N, 3, 3)`` its orientation, or ``None`` when not measured.
        rows: ``(N,)`` file rows (header = row 1).
        source: the file's name, for messages.
    """

    joint_names: tuple[str, ...]
    Q: FloatArray
    p_tracker_marker: FloatArray
    R_tracker_marker: FloatArray | None
    rows: tuple[int, ...]
    source: str

    def __len__(self) -> int:
        return len(self.Q)


def read_tracker_table(path: str | os.PathLike[str], columns: TrackerColumns) -> TrackerTable:
    """The tracker table at ``path`` read with ``columns`` (module docstring).

    Raises:
        InputError: a column missing, a field not a finite number, units mixed up, or fewer than
            :data:`MIN_TRACKER_ROWS` rows, naming the file, row and column.
    """
    path = Path(path)
    wanted = [*columns.joints, *columns.position, *columns.orientation]
    header, rows, records = read_table(path, wanted)
    if len(records) < MIN_TRACKER_ROWS:
        raise InputError(
            f"{len(records)} posture(s); at least {MIN_TRACKER_ROWS} are needed (the tracker's and marker's "
            "frames, and one posture held out)",
            file=path,
        )
    values = to_float(path, header, rows, records, wanted)
    nj = len(columns.joints)
    Q, p, o = values[:, :nj], values[:, nj : nj + 3], values[:, nj + 3 :]
    _check_angles(path, rows, Q, list(columns.joints), "joint value")
    if columns.position_unit == "m":
        check_positions(p, "", limit=MAX_POSITION_M, unit="m", file=path, rows=rows, columns=list(columns.position))
    else:
        check_positions(
            p, "", limit=MAX_POSITION_M * 1e3, unit="mm", file=path, rows=rows, columns=list(columns.position)
        )
        if np.max(np.abs(p)) < MIN_EXTENT_MM:
            raise InputError(
                f"every position is within ±{MIN_EXTENT_MM:g} mm: these look like metres (set unit = 'm')",
                file=path,
                column=columns.position[0],
            )
        p = p * 1e-3
    if columns.six_d and columns.angle_unit == "deg" and columns.orientation_kind != "quaternion_xyzw":
        _check_degrees(path, o, Q, columns)
    R = _rotations(path, rows, o, columns) if columns.six_d else None
    return TrackerTable(tuple(columns.joints), Q, p, R, tuple(rows), str(path))


def _check_angles(path: Path, rows: list[int], values: FloatArray, names: list[str], what: str) -> None:
    """Refuse a value beyond ±2π (radians expected), naming its row and column: degrees?"""
    bad = np.argwhere(np.abs(values) > MAX_ANGLE_RAD)
    if bad.size:
        k, c = (int(i) for i in bad[0])
        raise InputError(
            f"{what} {values[k, c]:g} is beyond ±2π: these look like degrees (radians expected)",
            file=path,
            row=rows[k],
            column=names[c],
        )


def _check_degrees(path: Path, o: FloatArray, Q: FloatArray, columns: TrackerColumns) -> None:
    """Refuse orientation angles ``o`` stated in degrees that are radians, from the data: every one
    within ±π while a joint of ``Q`` turns by :data:`MIN_JOINT_TURN_RAD` or more (the marker would
    have turned by a few degrees at most), naming the column of the largest angle."""
    largest = np.abs(o).max(axis=0)
    joint_turn = float(np.ptp(Q, axis=0).max()) if Q.size else 0.0
    if largest.max() > np.pi or joint_turn < MIN_JOINT_TURN_RAD:
        return
    c = int(np.argmax(largest))
    raise InputError(
        f"orientation stated in degrees (unit = 'deg'), but every angle is within ±π (largest {largest[c]:.4g}) "
        f"while the joints turn by up to {joint_turn:.3g} rad: these look like radians (set unit = 'rad')",
        file=path,
        column=columns.orientation[c],
    )


def _rotations(path: Path, rows: list[int], o: FloatArray, columns: TrackerColumns) -> FloatArray:
    """``(N, 3, 3)`` rotations of the orientation columns ``o`` in ``columns``' convention."""
    names = list(columns.orientation)
    if columns.orientation_kind == "quaternion_xyzw":
        norm = np.linalg.norm(o, axis=1)
        bad = np.flatnonzero(np.abs(norm - 1.0) > QUATERNION_NORM_TOL)
        if bad.size:
            k = int(bad[0])
            raise InputError(
                f"quaternion of norm {norm[k]:.6g}, not a unit quaternion", file=path, row=rows[k], column=names[0]
            )
        return Rotation.from_quat(o).as_matrix()
    angles = np.radians(o) if columns.angle_unit == "deg" else o
    if columns.orientation_kind == "rotation_vector":
        _check_angles(path, rows, np.linalg.norm(angles, axis=1)[:, None], names[:1], "rotation angle (rad)")
        return Rotation.from_rotvec(angles).as_matrix()
    _check_angles(path, rows, angles, names, "angle (rad)")
    return Rotation.from_euler("xyz", angles).as_matrix()
