"""Simulated recordings for identifying any arm: touches of fixed points, and a tracker watching a marker.

A *physical* arm is the nominal one (its URDF) with every joint origin between the base and the
flange off by a small random motion (:func:`arm_errors`, the parameterisation of
:func:`~brachycal.calibration.robot.identification.corrected_robot`). Two protocols record it:

- touches (MUKCa's): a tip fixed to the flange is put exactly on ``K`` fixed points at several
  places, each touch from its own posture (inverse kinematics of the physical arm from random
  starts), and the joint readings are then off by the least joint motion that moves the tip by a
  Gaussian error of ``noise_sd_m`` per axis (:func:`simulate_touches`); written as place folders
  of ``hole_k.csv`` (:func:`write_touch_places`, :mod:`brachycal.data.formats.touches`);
- a tracker (FIGAROH's): random postures within the limits, the marker's pose
  ``T_tracker_base · T_base_flange(q) · T_flange_marker`` with Gaussian noise on its position
  (per axis) and orientation (a rotation vector per axis) (:func:`simulate_tracker`); written as a
  CSV table and its column spec (:func:`write_tracker_table`, :mod:`brachycal.data.formats.tracker_table`).

Without noise the recordings are exact (round-off only): the identification recovers the physical
arm to nanometres in forward-kinematics terms. Units: metres and radians; frames as named.
Deterministic: the same seed gives the same numbers.
"""

from __future__ import annotations

import csv
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from brachycal.calibration.robot.arm_fit import ParameterSelection, corrected_robot, flange_points
from brachycal.calibration.robot.touches import arm_joints
from brachycal.data.formats.tracker_table import COLUMNS_FORMAT
from brachycal.io import atomic_open
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray

__all__ = [
    "TouchRecording",
    "TrackerRecording",
    "arm_errors",
    "simulate_touches",
    "simulate_tracker",
    "touch_postures",
    "tracker_columns_text",
    "write_touch_places",
    "write_touch_table",
    "write_tracker_table",
]

#: Inverse-kinematics steps per start, and starts per touch at most (a start that does not reach
#: the point within the limits is dropped).
IK_STEPS = 60
IK_STARTS = 200
#: A touch is exact when the tip is this close to its point (metres): round-off.
IK_TOLERANCE_M = 1e-13
#: The largest joint step of one Newton iteration (radians or metres): keeps far starts stable.
IK_MAX_STEP = 0.5
#: Random postures keep this far inside each joint's limits (radians or metres).
LIMIT_MARGIN = 0.1


def arm_errors(
    robot: Robot, flange: str, translation_sd_m: float, rotation_sd_rad: float, rng: np.random.Generator
) -> FloatArray:
    """``(nq, 6)`` random joint-origin corrections ``(v, ω)`` of the joints between the base and
    ``flange`` (Gaussian, SD ``translation_sd_m`` per axis of ``v``, ``rotation_sd_rad`` of ``ω``);
    zero for every other joint."""
    free = ParameterSelection.chain(robot, flange).free
    errors = np.zeros((robot.nq, 6))
    draws = np.c_[
        rng.normal(0.0, translation_sd_m, (robot.nq, 3)),
        rng.normal(0.0, rotation_sd_rad, (robot.nq, 3)),
    ]
    errors[free] = draws[free]
    return errors


def _arm_index(robot: Robot, flange: str) -> np.ndarray:
    names = list(robot.joint_names)
    return np.array([names.index(n) for n in arm_joints(robot, flange)])


def _tip_jacobian(
    robot: Robot, q: FloatArray, flange: str, tip: FloatArray, index: np.ndarray
) -> tuple[FloatArray, FloatArray]:
    """``(p (3,), J (3, len(index)))``: the tip in the base frame and its derivative by the arm's joints
    (a joint's motion is the correction of its origin along its axis: a turn, or a slide)."""
    fp = flange_points(robot, q[None], flange, tip)
    J = np.zeros((3, len(index)))
    for k, j in enumerate(index):
        name = robot.joint_names[j]
        at = 6 * j if robot.in_metres[j] else 6 * j + 3
        J[:, k] = fp.J_c[0, :, at : at + 3] @ robot.joint_axis(name)
    return fp.p[0], J


def _random_posture(robot: Robot, index: np.ndarray, rng: np.random.Generator) -> FloatArray:
    q = robot.neutral().copy()
    lower, upper = robot.lower[index] + LIMIT_MARGIN, robot.upper[index] - LIMIT_MARGIN
    q[index] = rng.uniform(lower, upper)
    return q


def touch_postures(
    robot: Robot, flange: str, tip: FloatArray, point: FloatArray, n: int, rng: np.random.Generator
) -> FloatArray:
    """``(n, nq)`` postures of ``robot`` putting ``tip`` (metres in ``flange``) exactly on ``point``
    (metres, base frame), each from a random start within the limits (Newton's least-norm steps).

    Raises:
        ValueError: the point is out of reach (no start of :data:`IK_STARTS` reached it).
    """
    index = _arm_index(robot, flange)
    tip, point = np.asarray(tip, dtype=float), np.asarray(point, dtype=float)
    out: list[FloatArray] = []
    for _ in range(IK_STARTS * n):
        q = _random_posture(robot, index, rng)
        for _ in range(IK_STEPS):
            p, J = _tip_jacobian(robot, q, flange, tip, index)
            if np.linalg.norm(p - point) < IK_TOLERANCE_M:
                break
            step = np.linalg.pinv(J) @ (p - point)
            q[index] -= step * min(1.0, IK_MAX_STEP / max(float(np.abs(step).max()), 1e-300))
        p, _ = _tip_jacobian(robot, q, flange, tip, index)
        if np.linalg.norm(p - point) < IK_TOLERANCE_M and robot.within_limits(q):
            out.append(q)
            if len(out) == n:
                return np.array(out)
    raise ValueError(f"point {point.tolist()} m: out of reach of the tip (no posture within the limits)")


@dataclass(frozen=True)
class TouchRecording:
    """Touches of fixed points by a physical arm, and their truth.

    Attributes:
        nominal: the arm's URDF (the model an identification starts from).
        physical: the arm that touched (``nominal`` corrected by ``corrections``).
        corrections: ``(nq, 6)`` the joint-origin corrections ``(v, ω)``, metres and radians.
        flange: the frame the tip is fixed to.
        tip: ``(3,)`` the tip in ``flange``, metres.
        points: per place, ``(K, 3)`` its fixed points, metres, base frame.
        touches: per place, per point, ``(N, nq)`` the joint readings of its touches (radians;
            metres for a prismatic joint), noise included.
        joints: the arm's joints between the base and ``flange``: the columns of a touch table.
        noise_sd_m: SD per axis of the tip's error the readings' noise makes, metres.
    """

    nominal: Robot
    physical: Robot
    corrections: FloatArray
    flange: str
    tip: FloatArray
    points: dict[str, FloatArray]
    touches: dict[str, tuple[FloatArray, ...]]
    joints: tuple[str, ...]
    noise_sd_m: float


def simulate_touches(
    nominal: Robot,
    flange: str,
    tip: FloatArray,
    places: Mapping[str, FloatArray],
    *,
    corrections: FloatArray,
    touches: int = 10,
    noise_sd_m: float = 0.0,
    seed: int | Sequence[int] = 0,
) -> TouchRecording:
    """Touches of the points of ``places`` (name: ``(K, 3)`` points, metres, base frame) by
    ``nominal`` corrected by ``corrections`` (``(nq, 6)``, :func:`arm_errors`), ``touches`` per
    point, with the tip ``tip`` (metres in ``flange``) (module docstring).

    ``noise_sd_m`` 0: every touch puts the physical arm's tip on its point to round-off.
    """
    rng = np.random.default_rng(seed)
    tip = np.asarray(tip, dtype=float)
    physical = corrected_robot(nominal, np.asarray(corrections, dtype=float))
    index = _arm_index(nominal, flange)
    recorded: dict[str, tuple[FloatArray, ...]] = {}
    for name, points in places.items():
        tables = []
        for point in np.asarray(points, dtype=float):
            Q = touch_postures(physical, flange, tip, point, touches, rng)
            for q in Q:
                _, J = _tip_jacobian(physical, q, flange, tip, index)
                q[index] += np.linalg.pinv(J) @ rng.normal(0.0, noise_sd_m, 3)
            tables.append(Q)
        recorded[name] = tuple(tables)
    return TouchRecording(
        nominal,
        physical,
        np.asarray(corrections, dtype=float),
        flange,
        tip,
        {name: np.asarray(p, dtype=float) for name, p in places.items()},
        recorded,
        arm_joints(nominal, flange),
        float(noise_sd_m),
    )


def _number(value: float) -> str:
    return repr(float(value))


def write_touch_table(path: str | os.PathLike[str], recording: TouchRecording, place: str, k: int) -> Path:
    """Write the touches of point ``k`` of ``place`` as a touch table (MUKCa's ``hole_k.csv``: one
    row per touch, the arm's joint values in :attr:`TouchRecording.joints` order, no header, full
    precision); all or nothing."""
    index = _arm_index(recording.nominal, recording.flange)
    with atomic_open(path) as handle:
        writer = csv.writer(handle, lineterminator="\n")
        writer.writerows([_number(v) for v in q[index]] for q in recording.touches[place][k])
    return Path(path)


def write_touch_places(folder: str | os.PathLike[str], recording: TouchRecording) -> list[Path]:
    """Write each place of ``recording`` as a folder ``folder/<place>`` of ``hole_k.csv``
    (:func:`write_touch_table`); returns the place folders."""
    places = []
    for name, tables in recording.touches.items():
        (Path(folder) / name).mkdir(parents=True, exist_ok=True)
        for k in range(len(tables)):
            write_touch_table(Path(folder) / name / f"hole_{k}.csv", recording, name, k)
        places.append(Path(folder) / name)
    return places


@dataclass(frozen=True)
class TrackerRecording:
    """A tracker's measurements of a marker on a physical arm, and their truth.

    Attributes:
        nominal, physical, corrections, flange: as :class:`TouchRecording`'s.
        T_tracker_base: ``(4, 4)`` the arm's base in the tracker's frame (metres).
        T_flange_marker: ``(4, 4)`` the marker on the flange (metres).
        Q: ``(N, nq)`` the postures (radians; metres for a prismatic joint).
        p: ``(N, 3)`` the marker's measured positions in the tracker's frame, metres.
        R: ``(N, 3, 3)`` its measured orientations.
        joints: the arm's joints (the table's joint columns).
        noise_sd_m, noise_sd_rad: SD per axis of the position and of the orientation's rotation vector.
    """

    nominal: Robot
    physical: Robot
    corrections: FloatArray
    flange: str
    T_tracker_base: FloatArray
    T_flange_marker: FloatArray
    Q: FloatArray
    p: FloatArray
    R: FloatArray
    joints: tuple[str, ...]
    noise_sd_m: float
    noise_sd_rad: float


def simulate_tracker(
    nominal: Robot,
    flange: str,
    T_tracker_base: FloatArray,
    T_flange_marker: FloatArray,
    *,
    corrections: FloatArray,
    postures: int = 30,
    noise_sd_m: float = 0.0,
    noise_sd_rad: float = 0.0,
    seed: int | Sequence[int] = 0,
) -> TrackerRecording:
    """``postures`` random postures within the limits of ``nominal`` corrected by ``corrections``,
    and the marker's pose a tracker reads at each (module docstring); noise 0: exact."""
    rng = np.random.default_rng(seed)
    physical = corrected_robot(nominal, np.asarray(corrections, dtype=float))
    index = _arm_index(nominal, flange)
    Q = np.array([_random_posture(nominal, index, rng) for _ in range(postures)])
    T = np.asarray(T_tracker_base) @ physical.fk(flange, Q) @ np.asarray(T_flange_marker)
    p = T[:, :3, 3] + rng.normal(0.0, noise_sd_m, (postures, 3))
    R = Rotation.from_rotvec(rng.normal(0.0, noise_sd_rad, (postures, 3))).as_matrix() @ T[:, :3, :3]
    return TrackerRecording(
        nominal,
        physical,
        np.asarray(corrections, dtype=float),
        flange,
        np.asarray(T_tracker_base, dtype=float),
        np.asarray(T_flange_marker, dtype=float),
        Q,
        p,
        R,
        arm_joints(nominal, flange),
        float(noise_sd_m),
        float(noise_sd_rad),
    )


#: The simulated table's marker columns: position (millimetres) and orientation (rotation vector, radians).
TRACKER_POSITION_COLUMNS = ("x_mm", "y_mm", "z_mm")
TRACKER_ORIENTATION_COLUMNS = ("rx_rad", "ry_rad", "rz_rad")


def tracker_columns_text(joints: tuple[str, ...], *, comment: str = "") -> str:
    """The column spec (:func:`~brachycal.data.formats.tracker_table.read_tracker_columns`) of
    :func:`write_tracker_table`'s tables: ``joints``, the position in millimetres, the orientation
    as a rotation vector in radians; ``comment`` lines first."""
    head = "".join(f"# {line}\n" for line in comment.splitlines())
    quoted = ", ".join(f'"{name}"' for name in joints)
    position = ", ".join(f'"{name}"' for name in TRACKER_POSITION_COLUMNS)
    orientation = ", ".join(f'"{name}"' for name in TRACKER_ORIENTATION_COLUMNS)
    return (
        f'{head}format = "{COLUMNS_FORMAT}"\njoints = [{quoted}]\n\n'
        f'[position]\ncolumns = [{position}]\nunit = "mm"\n\n'
        f'[orientation]\ncolumns = [{orientation}]\nkind = "rotation_vector"\nunit = "rad"\n'
    )


def write_tracker_table(path: str | os.PathLike[str], recording: TrackerRecording) -> Path:
    """Write ``recording`` as a tracker table: a header (the arm's joints, then
    :data:`TRACKER_POSITION_COLUMNS` and :data:`TRACKER_ORIENTATION_COLUMNS`), one row per posture,
    full precision; all or nothing."""
    index = _arm_index(recording.nominal, recording.flange)
    rotvec = Rotation.from_matrix(recording.R).as_rotvec()
    with atomic_open(path) as handle:
        writer = csv.writer(handle, lineterminator="\n")
        writer.writerow([*recording.joints, *TRACKER_POSITION_COLUMNS, *TRACKER_ORIENTATION_COLUMNS])
        for q, p, r in zip(recording.Q, recording.p, rotvec, strict=True):
            writer.writerow([*map(_number, q[index]), *(_number(v * 1e3) for v in p), *map(_number, r)])
    return Path(path)
