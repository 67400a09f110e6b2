"""Example files made by the twin: a tracked-pointer pivot recording, PLUS N-wire files, phantom sessions.

What ``brachycal pivot`` and ``brachycal nwire`` read in a lab comes from other software: a pose
list from a tracker (SciKit-Surgery's CSV form: ``timestamp_ns,m00,…,m33``, millimetres) and a
PLUS device-set configuration with the segmented frames of an fCal session. This module writes
the same formats from simulated data with a known truth, so that the commands can be shown on
files that ship with brachycal (``examples/pivot``, ``examples/nwire``; the real recordings stay
outside, the documentation's reference data). ``examples/phantom`` holds a multi-wedge and an arbitrary-wire session
of the twin in brachycal's own phantom formats (:mod:`brachycal.calibration.phantom.phantom_file`), for
``brachycal phantom``; ``examples/temporal`` a PLUS water-tank video and tracker pair with a known lag,
for ``brachycal temporal``; ``examples/touches`` and ``examples/tracker`` a Panda's touches of fixed
points and a UR10's tracker table (:mod:`brachycal.simulation.arm_touches`), for ``brachycal robot
identify``; ``examples/stepper`` PLUS iCal recordings of a TRUS probe on a brachytherapy stepper with
its device set (:mod:`brachycal.studies.stepper_twin`), for ``brachycal stepper``. Every file here is
read back by the real readers
(:func:`~brachycal.data.pose_list.read_pose_list`, :func:`~brachycal.data.formats.plus_files.read_plus_config`,
:func:`~brachycal.data.formats.plus_files.read_segmented_frames`,
:func:`~brachycal.calibration.phantom.phantom_file.read_observations`) in the tests and calibrated to its truth.

Deterministic: the same seed gives the same numbers; numbers are written with Python's shortest
round-trip form (``repr``), so that the files hold exactly what was simulated.
"""

from __future__ import annotations

import csv
import os
import re
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from brachycal.calibration.phantom.phantom_file import write_observations
from brachycal.data.formats.metaimage import write_image_sequence
from brachycal.data.formats.plus_files import PlusConfig, SegmentedFrame
from brachycal.data.pose_list import COLUMNS
from brachycal.io import OutputSet, atomic_open, bundled, json_text, output_set
from brachycal.model.description import load_robot
from brachycal.se3 import FloatArray, inverse, make_transform
from brachycal.simulation.arm_touches import (
    TouchRecording,
    TrackerRecording,
    arm_errors,
    simulate_touches,
    simulate_tracker,
    tracker_columns_text,
    write_touch_table,
    write_tracker_table,
)
from brachycal.studies.nwire_twin import FCAL2_LANDMARKS_MM, NWireSimConfig, simulate_nwire
from brachycal.studies.phantom_twin import simulate_phantom
from brachycal.studies.plus_device_set import (
    add_phantom_definition,
    add_probe_calibration_algo,
    numbers_text,
    write_xml,
)
from brachycal.studies.stepper_twin import STEPPER_NAMES, write_stepper_files
from brachycal.studies.tank_recording import write_tank_files

__all__ = [
    "NWIRE_CONFIG_NAME",
    "NWIRE_FRAMES_NAME",
    "NWIRE_SEQUENCE_NAMES",
    "PHANTOM_FILES",
    "PHANTOM_FRAMES",
    "PHANTOM_TRUTH_NAME",
    "PIVOT_NAME",
    "TEMPORAL_LAG_S",
    "TEMPORAL_NAMES",
    "TOUCH_PLACES",
    "TOUCH_TRUTH_NAME",
    "TRACKER_NAMES",
    "PivotRecording",
    "phantom_geometry_text",
    "render_wire_frame",
    "simulate_pivot_recording",
    "simulate_robot_examples",
    "write_example_files",
    "write_plus_config",
    "write_pose_list",
    "write_segmented_frames",
]

MM = 1e-3
#: File names in ``examples/`` (and ``brachycal examples DIR``).
PIVOT_NAME = "pivot/pointer_pivot.csv"
NWIRE_CONFIG_NAME = "nwire/PlusDeviceSet_twin_fCal2.xml"
NWIRE_FRAMES_NAME = "nwire/twin_segmented_frames.xml"
#: The phantom sessions' files per method: (geometry TOML, observations CSV, the geometry's kind).
PHANTOM_FILES = {
    "wedge": ("phantom/multi_wedge.toml", "phantom/wedge_observations.csv", "multi-wedge"),
    "wire": ("phantom/arbitrary_wire.toml", "phantom/wire_observations.csv", "wire"),
}
PHANTOM_TRUTH_NAME = "phantom/truth.json"
#: The N-wire example's frames rendered as tracked B-mode sequences (calibration, validation), for
#: ``brachycal nwire segment``; how many of the example's frames each holds (~3 kB a frame, compressed).
NWIRE_SEQUENCE_NAMES = ("nwire/twin_calibration.mha", "nwire/twin_validation.mha")
NWIRE_SEQUENCE_FRAMES = (20, 10)
#: Width of a rendered wire echo (Gaussian σ, pixels): a 0.5 mm wire is ~3 px across at 0.19 mm/px.
NWIRE_ECHO_SIGMA_PX = 1.2
#: The water-tank pair for ``brachycal temporal`` (video, tracker, truth) and its known lag, seconds.
TEMPORAL_NAMES = ("temporal/tank_video.mha", "temporal/tank_tracker.mha", "temporal/truth.json")
TEMPORAL_LAG_S = 0.137
#: The pair's length and sampling, seconds: 80 frames at 10 Hz, the tracker at 20 Hz (~140 kB together).
_TEMPORAL_DURATION_S, _TEMPORAL_VIDEO_PERIOD_S, _TEMPORAL_TRACKER_PERIOD_S = 8.0, 0.1, 0.05
#: Frames of the phantom examples: small files (~100 kB together), and enough that neither fit draws
#: the conditioning warning (predicted SD 50 mm from the image centre above 0.5 mm with the fit's
#: residual level): with seed 0 the multi-wedge's is 0.57 mm at 30 frames, 0.44 mm at 50.
PHANTOM_FRAMES = {"wedge": 50, "wire": 30}
#: Seeds of the example files' random streams (tagged so that they never coincide with the twin's).
_PIVOT_TAG = 0x5056
_TOUCH_TAG, _TRACKER_TAG = 0x544F, 0x5452
#: The touch example (``brachycal robot identify touches``): a Panda (the bundled description) with
#: its joint origins off by 0.3 mm / 0.05 deg per axis, a ball held at the hand's tool centre point
#: (``panda_hand_tcp``: the ball's nominal place; the true one ~1 mm off it) touching two sockets
#: 50 mm apart at three places (base frame, metres), 8 touches each, with 0.05 mm of noise per axis
#: at the ball. Files ``touches/<place>/hole_k.csv`` and the truth.
TOUCH_ROBOT, TOUCH_FLANGE, TOUCH_TOOL_FRAME = "panda", "panda_link8", "panda_hand_tcp"
TOUCH_TIP_M = (0.4e-3, -0.3e-3, 0.1042)
TOUCH_PLACES = {
    "front": ((0.45, 0.0, 0.10), (0.50, 0.0, 0.10)),
    "left": ((0.40, 0.30, 0.15), (0.45, 0.30, 0.15)),
    "right": ((0.40, -0.30, 0.15), (0.45, -0.30, 0.15)),
}
TOUCH_DISTANCE_MM = 50.0
TOUCH_TRUTH_NAME = "touches/truth.json"
_TOUCHES_PER_POINT, _TOUCH_NOISE_M = 8, 0.05e-3
#: The tracker example (``brachycal robot identify tracker``): a UR10 (the bundled description) off
#: by 0.5 mm / 0.05 deg per joint-origin axis, a 6-D marker on its flange seen by a tracker 2 m
#: away, 24 random postures, 0.1 mm and 0.05 deg of noise per axis. Files: the table, its column
#: spec and the truth.
TRACKER_ROBOT, TRACKER_FLANGE = "ur10", "tool0"
TRACKER_NAMES = ("tracker/table.csv", "tracker/columns.toml", "tracker/truth.json")
TRACKER_T_TRACKER_BASE = make_transform(Rotation.from_rotvec([0.1, -0.2, 2.5]).as_matrix(), [2.1, 0.4, -0.3])
TRACKER_T_FLANGE_MARKER = make_transform(Rotation.from_rotvec([0.3, 0.2, -0.1]).as_matrix(), [0.03, -0.02, 0.08])
_TRACKER_POSTURES, _TRACKER_NOISE_M, _TRACKER_NOISE_DEG = 24, 0.1e-3, 0.05


@dataclass(frozen=True)
class PivotRecording:
    """A tracked pointer pivoting about a fixed point, as a tracker reports it.

    Attributes:
        timestamps_ns: ``(N,)`` the tracker's time stamps, nanoseconds.
        T_tracker_marker_mm: ``(N, 4, 4)`` marker-to-tracker poses read, translations in millimetres.
        p_marker_tip_mm: ``(3,)`` true tip in the marker frame, millimetres.
        p_tracker_pivot_mm: ``(3,)`` true pivot point in the tracker frame, millimetres.
        noise_sd_mm: SD per axis of the reading's position error, millimetres.
        noise_sd_deg: SD per axis of the reading's rotation error, degrees.
    """

    timestamps_ns: np.ndarray
    T_tracker_marker_mm: FloatArray
    p_marker_tip_mm: FloatArray
    p_tracker_pivot_mm: FloatArray
    noise_sd_mm: float
    noise_sd_deg: float


def simulate_pivot_recording(
    seed: int = 0,
    poses: int = 200,
    *,
    p_marker_tip_mm: Sequence[float] = (-14.5, 395.7, -7.8),
    p_tracker_pivot_mm: Sequence[float] = (-140.0, 45.0, -1750.0),
    cone_deg: float = 30.0,
    noise_sd_mm: float = 0.25 / np.sqrt(3.0),
    noise_sd_deg: float = 0.02,
) -> PivotRecording:
    """A pointer pivoting about a fixed point, read by an optical tracker with noise.

    The pointer's shaft sweeps a cone of half-angle ``cone_deg`` about a mean direction (as a hand
    wobbles a pointer in a divot) and spins about it; each pose is read with a position error of
    ``noise_sd_mm`` per axis (default 0.25 mm 3D RMS: an NDI Polaris Spectra's stated volumetric
    accuracy, as :mod:`~brachycal.studies.nwire_twin` uses) and a rotation error of
    ``noise_sd_deg`` per axis. The defaults place tip and pivot where the real SciKit-Surgery
    recording has them in size (a 0.4 m pointer, the pivot ~1.75 m from the tracker).

    Args:
        seed: random seed.
        poses: number of poses N.
        p_marker_tip_mm: ``(3,)`` tip in the marker frame, millimetres.
        p_tracker_pivot_mm: ``(3,)`` pivot point in the tracker frame, millimetres.
        cone_deg: largest tilt of the shaft from its mean direction, degrees.
        noise_sd_mm, noise_sd_deg: the reading's errors (see above).
    """
    rng = np.random.default_rng([seed, _PIVOT_TAG])
    tip = np.asarray(p_marker_tip_mm, dtype=float)
    pivot = np.asarray(p_tracker_pivot_mm, dtype=float)
    # Mean attitude: the shaft (marker -> tip) points away from the tracker, along +z of the tracker.
    shaft = tip / np.linalg.norm(tip)
    mean = Rotation.align_vectors([[0.0, 0.0, -1.0]], [shaft])[0]
    # Tilt uniformly over the cone's solid angle; spin about the shaft within ±60°.
    tilt = np.arccos(1.0 - rng.uniform(0.0, 1.0 - np.cos(np.radians(cone_deg)), poses))
    azimuth = rng.uniform(0.0, 2.0 * np.pi, poses)
    spin = rng.uniform(-np.pi / 3.0, np.pi / 3.0, poses)
    axis = np.column_stack([np.cos(azimuth), np.sin(azimuth), np.zeros(poses)])
    R = Rotation.from_rotvec(axis * tilt[:, None]) * mean * Rotation.from_rotvec(np.outer(spin, shaft))
    rotation_noise = Rotation.from_rotvec(rng.normal(scale=np.radians(noise_sd_deg), size=(poses, 3)))
    position_noise = rng.normal(scale=noise_sd_mm, size=(poses, 3))
    T = np.tile(np.eye(4), (poses, 1, 1))
    T[:, :3, :3] = (rotation_noise * R).as_matrix()
    T[:, :3, 3] = pivot - R.apply(tip) + position_noise
    # The tracker's clock: ~20 Hz with jitter (the real recording's stamps are 45-50 ms apart).
    steps = rng.integers(45_000_000, 50_000_000, poses)
    timestamps = 1_700_000_000_000_000_000 + np.cumsum(steps)
    return PivotRecording(timestamps, T, tip, pivot, float(noise_sd_mm), float(noise_sd_deg))


def write_pose_list(path: str | os.PathLike[str], names: Sequence[object], T: FloatArray, *, key: str) -> Path:
    """Write a pose list: a header ``<key>,m00,…,m33``, then one row-major ``(4, 4)`` per row.

    Args:
        path: the CSV file (a staging path of a live output set, or written all or nothing).
        names: ``(N,)`` the first column's values (time stamps, names).
        T: ``(N, 4, 4)`` the poses, in the units the reader is told (``brachycal pivot --units``).
        key: the first column's name (``timestamp_ns``).
    """
    with atomic_open(path) as handle:
        writer = csv.writer(handle, lineterminator="\n")
        writer.writerow([key, *COLUMNS])
        for name, matrix in zip(names, np.asarray(T, dtype=float), strict=True):
            writer.writerow([name, *(repr(float(v)) for v in matrix.ravel())])
    return Path(path)


def render_wire_frame(
    points_uv: FloatArray,
    rng: np.random.Generator,
    *,
    shape: tuple[int, int] = (616, 820),
    sigma_px: float = 3.0,
    noise: float = 1.0,
) -> np.ndarray:
    """A B-mode-like uint8 frame ``shape`` (rows, columns): dim background with Gaussian noise of SD
    ``noise``, a bright horizontal wall, and a Gaussian dot of σ ``sigma_px`` at each ``(u, v)`` of
    ``points_uv (N, 2)`` pixels. Without noise the frame compresses to a few kB."""
    image = 25.0 + rng.normal(0.0, noise, shape)
    image[560:566, 60:760] += 150.0  # a wall: long, removed by the bar top-hats
    reach = int(np.ceil(6 * sigma_px))  # the Gaussian is below 1e-7 of its peak beyond 6 σ
    for pu, pv in points_uv:
        v0, u0 = max(int(pv) - reach, 0), max(int(pu) - reach, 0)
        v, u = np.mgrid[v0 : int(pv) + reach + 1, u0 : int(pu) + reach + 1]
        image[v, u] += 200.0 * np.exp(-((u - pu) ** 2 + (v - pv) ** 2) / (2 * sigma_px**2))
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def write_wire_sequence(path: str | os.PathLike[str], frames: Sequence[SegmentedFrame], seed: int) -> None:
    """The wire points of ``frames`` rendered as a tracked B-mode sequence (PLUS .mha, tracker readings
    in mm) at :data:`NWIRE_SIZE_PX`, without background noise."""
    rng = np.random.default_rng(seed)
    width, height = NWIRE_SIZE_PX
    pixels = np.stack(
        [
            render_wire_frame(
                np.array(list(f.points_px.values())),
                rng,
                shape=(height, width),
                sigma_px=NWIRE_ECHO_SIGMA_PX,
                noise=0.0,
            )
            for f in frames
        ]
    )
    fields = []
    for f in frames:
        if f.T_tracker_probe is None or f.T_tracker_reference is None:
            raise ValueError(f"frame {f.index}: no tracker readings to write")
        fields.append(
            {
                "ProbeToTrackerTransform": numbers_text(_mm(f.T_tracker_probe)),
                "ReferenceToTrackerTransform": numbers_text(_mm(f.T_tracker_reference)),
            }
        )
    write_image_sequence(path, pixels, frame_fields=fields)


def _mm(T: FloatArray) -> FloatArray:
    """A transform with its translation in millimetres (PLUS's unit)."""
    T = np.array(T, dtype=float)
    T[:3, 3] /= MM
    return T


def write_plus_config(path: str | os.PathLike[str], config: PlusConfig, *, name: str) -> Path:
    """Write a PLUS device-set configuration holding what fCal's probe calibration reads.

    The elements PLUS's own files have for it (``PlusDeviceSet_fCal_*.xml``): ``CoordinateDefinitions``
    (each transform ``From``→``To`` in millimetres; Phantom→Reference is the phantom's landmark
    registration), ``Segmentation`` with the approximate pixel spacing, ``PhantomDefinition`` with
    the N-wire patterns and landmarks (millimetres, phantom frame) and the calibration algorithm's
    frame names. No devices: the data come from the segmented-frames file.

    Args:
        path: the XML file.
        config: the phantom and transforms (metres, as
            :func:`~brachycal.data.formats.plus_files.read_plus_config` returns).
        name: the device set's name.
    """
    root = ET.Element("PlusConfiguration", version="2.1")
    collection = ET.SubElement(root, "DataCollection", StartupDelaySec="1.0")
    ET.SubElement(
        collection,
        "DeviceSet",
        Name=name,
        Description="Simulated by brachycal's twin: static captures of an fCal 2.0 phantom (3 N-wires)",
    )
    definitions = ET.SubElement(root, "CoordinateDefinitions")
    for (source, target), T in config.transforms.items():
        ET.SubElement(definitions, "Transform", From=source, To=target, Matrix=numbers_text(_mm(T)))
    if config.approximate_spacing_m is not None:
        ET.SubElement(root, "Segmentation", ApproximateSpacingMmPerPixel=repr(config.approximate_spacing_m / MM))
    patterns_mm = [
        [(wire.name, wire.front_m / MM, wire.back_m / MM) for wire in pattern] for pattern in config.patterns
    ]
    geometry = add_phantom_definition(root, patterns_mm, name="fCAL", version="2.0", wiring_version="2.0")
    landmarks = ET.SubElement(geometry, "Landmarks")
    for k, p in enumerate(FCAL2_LANDMARKS_MM):
        ET.SubElement(landmarks, "Landmark", Name=f"#{k + 1}", Position=numbers_text(p))
    add_probe_calibration_algo(root, "Reference")
    write_xml(path, root)
    return Path(path)


def _frames_element(parent: ET.Element, tag: str, frames: Sequence[SegmentedFrame], period_s: float) -> None:
    element = ET.SubElement(parent, tag)
    for index, frame in enumerate(frames):  # PLUS counts each set's frames from 0
        status = "OK" if frame.ok else "Failed"
        node = ET.SubElement(element, "Frame", Index=str(index), SegmentationStatus=status)
        if not frame.ok:
            continue
        points = ET.SubElement(node, "SegmentedPoints")
        for wire, uv in frame.points_px.items():
            ET.SubElement(points, "Point", WireName=wire, Position=f"{numbers_text(uv)} 0")
        time_s = repr(round(frame.index * period_s, 6))  # one clock over both sets
        tracked = ET.SubElement(node, "TrackedFrame", Timestamp=time_s, ImageDataValid="true")
        for field, T in (
            ("ProbeToTrackerTransform", frame.T_tracker_probe),
            ("ReferenceToTrackerTransform", frame.T_tracker_reference),
        ):
            if T is None:  # an OK frame carries both readings (read_segmented_frames demands them)
                raise ValueError(f"frame {frame.index}: no {field}")
            ET.SubElement(tracked, "CustomFrameField", Name=field, Value=numbers_text(_mm(T)))
            ET.SubElement(tracked, "CustomFrameField", Name=field + "Status", Value="OK")
        ET.SubElement(tracked, "CustomFrameField", Name="Timestamp", Value=time_s)


def write_segmented_frames(
    path: str | os.PathLike[str],
    calibration: Sequence[SegmentedFrame],
    validation: Sequence[SegmentedFrame],
    *,
    period_s: float = 0.5,
) -> Path:
    """Write a PLUS probe-calibration results file stripped to its inputs, as PLUS's own are read.

    ``<ProbeCalibrationResult><Data>`` with ``<ValidationData>`` and ``<CalibrationData>``, each a
    list of ``<Frame Index SegmentationStatus>`` holding the segmented wire points
    (``<Point WireName Position="u v 0">``, pixels) and the tracker readings
    (``CustomFrameField`` ``ProbeToTrackerTransform`` / ``ReferenceToTrackerTransform``, row-major
    ``(4, 4)``, millimetres) with their status and time stamp (``period_s`` apart, seconds).
    """
    root = ET.Element("ProbeCalibrationResult", version="2.0")
    data = ET.SubElement(root, "Data")
    _frames_element(data, "ValidationData", validation, period_s)
    _frames_element(data, "CalibrationData", calibration, period_s)
    write_xml(path, root)
    return Path(path)


#: The N-wire example's truth: the image on the probe's marker body (PLUS's "Probe" frame). The
#: image's u axis along the marker's -y, depth along -z, 30 mm below and 12 mm beside the marker
#: (a marker body clamped to the probe's handle), and an anisotropic spacing (the scanner's depth
#: scale differs from its lateral one, as the twin's speed of sound makes it).
NWIRE_T_PROBE_IMAGE = make_transform(
    Rotation.from_euler("xyz", [178.0, 2.0, 91.0], degrees=True).as_matrix(), [0.012, 0.045, -0.030]
)
NWIRE_SPACING_M = np.array([0.19e-3, 0.1828e-3])
NWIRE_SIZE_PX = (1080, 720)


#: The bundled geometries' registration paragraph: its comment lines and the matrix line.
_REGISTRATION = re.compile(
    r"^# The phantom's pose on its reference body.*?^T_reference_phantom_mm = [^\n]*\n", re.MULTILINE | re.DOTALL
)


def phantom_geometry_text(method: str, T_reference_phantom: FloatArray, *, seed: int) -> str:
    """The bundled geometry of ``method`` (``"wedge"`` or ``"wire"``) with a lab's registration in it.

    The bundled file's text (its comments kept) with ``T_reference_phantom_mm`` replaced by
    ``T_reference_phantom`` (``(4, 4)``, metres; written in millimetres, full precision): the
    twin lab's landmark registration, as a lab's file holds its own.
    """
    name = PHANTOM_FILES[method][0].split("/")[-1]
    text = bundled("phantoms", name).read_text(encoding="utf-8")
    T = _mm(T_reference_phantom)
    rows = ", ".join("[" + ", ".join(repr(float(v)) for v in row) + "]" for row in T)
    paragraph = (
        "# The phantom's pose on its reference body (its registration: PLUS's Phantom->Reference), translation\n"
        f"# in mm: the twin lab's, from touching the landmarks below (brachycal examples, seed {seed}).\n"
        f"T_reference_phantom_mm = [{rows}]\n"
    )
    text, count = _REGISTRATION.subn(lambda _: paragraph, text)
    if count != 1:  # the bundled file's layout changed: say so rather than ship a file without the registration
        raise ValueError(f"the bundled {name} has no registration paragraph to replace")
    header = (
        f"# brachycal's example (examples/phantom/{name}): the bundled geometry with the twin lab's registration,\n"
        "# written by brachycal.studies.example_files (python examples/make_example_files.py).\n"
    )
    return header + text


def simulate_robot_examples(seed: int = 0) -> tuple[TouchRecording, TrackerRecording]:
    """The touch and tracker examples' recordings (:data:`TOUCH_PLACES`, :data:`TRACKER_NAMES`):
    a Panda's touches and a UR10 seen by a tracker, each arm off its URDF by random joint-origin errors."""
    panda = load_robot(TOUCH_ROBOT)
    rng = np.random.default_rng([seed, _TOUCH_TAG])
    touches = simulate_touches(
        panda,
        TOUCH_FLANGE,
        np.array(TOUCH_TIP_M),
        {name: np.array(points) for name, points in TOUCH_PLACES.items()},
        corrections=arm_errors(panda, TOUCH_FLANGE, 0.3e-3, float(np.radians(0.05)), rng),
        touches=_TOUCHES_PER_POINT,
        noise_sd_m=_TOUCH_NOISE_M,
        seed=[seed, _TOUCH_TAG, 1],
    )
    ur10 = load_robot(TRACKER_ROBOT)
    rng = np.random.default_rng([seed, _TRACKER_TAG])
    tracker = simulate_tracker(
        ur10,
        TRACKER_FLANGE,
        TRACKER_T_TRACKER_BASE,
        TRACKER_T_FLANGE_MARKER,
        corrections=arm_errors(ur10, TRACKER_FLANGE, 0.5e-3, float(np.radians(0.05)), rng),
        postures=_TRACKER_POSTURES,
        noise_sd_m=_TRACKER_NOISE_M,
        noise_sd_rad=float(np.radians(_TRACKER_NOISE_DEG)),
        seed=[seed, _TRACKER_TAG, 1],
    )
    return touches, tracker


def _corrections_json(robot_joints: Sequence[str], corrections: FloatArray) -> dict[str, list[float]]:
    """Per joint with a correction, ``[vx, vy, vz (m), wx, wy, wz (rad)]``."""
    return {name: c.tolist() for name, c in zip(robot_joints, corrections, strict=True) if np.any(c)}


def _touch_names() -> list[str]:
    return [f"touches/{place}/hole_{k}.csv" for place, points in TOUCH_PLACES.items() for k in range(len(points))]


def write_example_files(
    folder: str | os.PathLike[str], *, seed: int = 0, force: bool = False, outputs: OutputSet | None = None
) -> list[Path]:
    """Write the pivot, N-wire and phantom example files, each set with its truth, into ``folder``.

    Writes ``pivot/pointer_pivot.csv`` (:func:`simulate_pivot_recording`, 200 poses, millimetres),
    ``pivot/truth.json``, ``nwire/PlusDeviceSet_twin_fCal2.xml`` and ``nwire/twin_segmented_frames.xml``
    (:func:`~brachycal.studies.nwire_twin.simulate_nwire` with its default error sources, 40
    calibration and 20 validation frames) and ``nwire/truth.json``; and for ``brachycal phantom``
    (:data:`PHANTOM_FILES`) a multi-wedge and an arbitrary-wire session on the same probe
    (:func:`~brachycal.studies.phantom_twin.simulate_phantom`, its default error sources,
    :data:`PHANTOM_FRAMES` frames), each phantom's geometry with the session's landmark
    registration, and ``phantom/truth.json``; for ``brachycal temporal`` a water-tank video and
    tracker pair with a known lag (:data:`TEMPORAL_NAMES`, :data:`TEMPORAL_LAG_S`); and for
    ``brachycal nwire segment`` the first of the N-wire frames rendered as tracked B-mode sequences
    (:data:`NWIRE_SEQUENCE_NAMES`, :func:`write_wire_sequence`); for ``brachycal robot identify``
    a Panda's touches of fixed points (``touches/<place>/hole_k.csv``, :data:`TOUCH_PLACES`) and a
    UR10 seen by a tracker (:data:`TRACKER_NAMES`), each with its truth (:func:`simulate_robot_examples`);
    for ``brachycal stepper`` a stepper's device set, its five recordings and their truth
    (:data:`~brachycal.studies.stepper_twin.STEPPER_NAMES`). All or nothing; existing files are
    replaced only with ``force``.

    Returns:
        The paths written.
    """
    folder = Path(folder)
    pivot = simulate_pivot_recording(seed)
    sim = NWireSimConfig(seed=seed, calibration_frames=40, validation_frames=20)
    config, calibration, validation = simulate_nwire(NWIRE_T_PROBE_IMAGE, NWIRE_SPACING_M, NWIRE_SIZE_PX, sim)
    pivot_truth = {
        "what": "truth of pointer_pivot.csv (brachycal.studies.example_files.simulate_pivot_recording)",
        "seed": seed,
        "p_marker_tip_mm": pivot.p_marker_tip_mm.tolist(),
        "p_tracker_pivot_mm": pivot.p_tracker_pivot_mm.tolist(),
        "noise_sd_mm": pivot.noise_sd_mm,
        "noise_sd_deg": pivot.noise_sd_deg,
    }
    nwire_truth = {
        "what": "truth of the N-wire example (brachycal.studies.nwire_twin.simulate_nwire, default errors)",
        "seed": seed,
        "T_probe_image": NWIRE_T_PROBE_IMAGE.tolist(),
        "spacing_mm": (NWIRE_SPACING_M / MM).tolist(),
        "size_px": list(NWIRE_SIZE_PX),
        "T_image_probe": inverse(NWIRE_T_PROBE_IMAGE).tolist(),
    }
    phantoms = {
        method: simulate_phantom(
            method, NWIRE_T_PROBE_IMAGE, NWIRE_SPACING_M, NWIRE_SIZE_PX, sim, frames=PHANTOM_FRAMES[method]
        )
        for method in PHANTOM_FILES
    }
    phantom_truth = {
        "what": "truth of the phantom examples (brachycal.studies.phantom_twin.simulate_phantom, default errors): "
        "the image on the probe's marker body, as the N-wire example's",
        "seed": seed,
        "frames": PHANTOM_FRAMES,
        "T_marker_image": NWIRE_T_PROBE_IMAGE.tolist(),
        "spacing_mm": (NWIRE_SPACING_M / MM).tolist(),
        "size_px": list(NWIRE_SIZE_PX),
    }
    temporal_truth = {
        "what": "truth of the water-tank pair (brachycal.studies.tank_recording.write_tank_files, no noise): "
        "the tracker's lag behind the video, PLUS's TrackerLagSec",
        "lag_s": TEMPORAL_LAG_S,
        "duration_s": _TEMPORAL_DURATION_S,
        "video_period_s": _TEMPORAL_VIDEO_PERIOD_S,
        "tracker_period_s": _TEMPORAL_TRACKER_PERIOD_S,
    }
    names = [PIVOT_NAME, "pivot/truth.json", NWIRE_CONFIG_NAME, NWIRE_FRAMES_NAME, "nwire/truth.json"]
    names += [name for files in PHANTOM_FILES.values() for name in files[:2]] + [PHANTOM_TRUTH_NAME]
    names += list(TEMPORAL_NAMES) + list(NWIRE_SEQUENCE_NAMES) + list(STEPPER_NAMES.values())
    touch_rec, tracker_rec = simulate_robot_examples(seed)
    touch_truth = {
        "what": "truth of the touch example (brachycal.simulation.arm_touches.simulate_touches): the Panda that "
        "touched, its joint-origin corrections T_parent_joint <- T_parent_joint @ T(exp(w), v), metres and radians",
        "seed": seed,
        "robot": TOUCH_ROBOT,
        "flange": TOUCH_FLANGE,
        "tool_frame": TOUCH_TOOL_FRAME,
        "tip_m": touch_rec.tip.tolist(),
        "points_m": {name: points.tolist() for name, points in touch_rec.points.items()},
        "distance_mm": TOUCH_DISTANCE_MM,
        "corrections": _corrections_json(touch_rec.nominal.joint_names, touch_rec.corrections),
        "noise_sd_m": touch_rec.noise_sd_m,
        "joints": list(touch_rec.joints),
    }
    tracker_truth = {
        "what": "truth of the tracker example (brachycal.simulation.arm_touches.simulate_tracker): the UR10 seen, "
        "its joint-origin corrections (as the touch example's), the tracker's and the marker's frames (metres)",
        "seed": seed,
        "robot": TRACKER_ROBOT,
        "flange": TRACKER_FLANGE,
        "T_tracker_base": tracker_rec.T_tracker_base.tolist(),
        "T_flange_marker": tracker_rec.T_flange_marker.tolist(),
        "corrections": _corrections_json(tracker_rec.nominal.joint_names, tracker_rec.corrections),
        "noise_sd_m": tracker_rec.noise_sd_m,
        "noise_sd_deg": _TRACKER_NOISE_DEG,
    }
    names += [*_touch_names(), TOUCH_TRUTH_NAME, *TRACKER_NAMES]
    with output_set(outputs, force=force) as out:
        staged = {name: out.claim(folder / name, make_parents=True) for name in names}
        write_pose_list(staged[PIVOT_NAME], pivot.timestamps_ns.tolist(), pivot.T_tracker_marker_mm, key="timestamp_ns")
        staged["pivot/truth.json"].write_text(json_text(pivot_truth))
        write_plus_config(staged[NWIRE_CONFIG_NAME], config, name="brachycal twin: fCal 2.0 phantom, 3 N-wires")
        write_segmented_frames(staged[NWIRE_FRAMES_NAME], calibration, validation)
        staged["nwire/truth.json"].write_text(json_text(nwire_truth))
        for method, (geometry_name, observations_name, kind) in PHANTOM_FILES.items():
            session = phantoms[method]
            T_reference_phantom = session.phantom.geometry.registration()
            staged[geometry_name].write_text(phantom_geometry_text(method, T_reference_phantom, seed=seed))
            write_observations(staged[observations_name], kind, session.observations)
        staged[PHANTOM_TRUTH_NAME].write_text(json_text(phantom_truth))
        video, tracker, truth = TEMPORAL_NAMES
        write_tank_files(
            staged[video],
            staged[tracker],
            lag_s=TEMPORAL_LAG_S,
            duration_s=_TEMPORAL_DURATION_S,
            video_period_s=_TEMPORAL_VIDEO_PERIOD_S,
            tracker_period_s=_TEMPORAL_TRACKER_PERIOD_S,
        )
        staged[truth].write_text(json_text(temporal_truth))
        for name, frames, count in zip(
            NWIRE_SEQUENCE_NAMES, (calibration, validation), NWIRE_SEQUENCE_FRAMES, strict=True
        ):
            write_wire_sequence(staged[name], frames[:count], seed)
        for place, points in TOUCH_PLACES.items():
            for k in range(len(points)):
                write_touch_table(staged[f"touches/{place}/hole_{k}.csv"], touch_rec, place, k)
        staged[TOUCH_TRUTH_NAME].write_text(json_text(touch_truth))
        table, columns, truth_name = TRACKER_NAMES
        write_tracker_table(staged[table], tracker_rec)
        comment = (
            "brachycal's example (examples/tracker/table.csv): a UR10's joints and a 6-D marker on its flange as a\n"
            "tracker reads it, position in millimetres, orientation as a rotation vector in radians."
        )
        staged[columns].write_text(tracker_columns_text(tracker_rec.joints, comment=comment))
        staged[truth_name].write_text(json_text(tracker_truth))
        write_stepper_files({key: staged[name] for key, name in STEPPER_NAMES.items()}, seed)
    return [folder / name for name in names]
