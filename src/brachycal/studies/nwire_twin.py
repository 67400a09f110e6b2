"""N-wire calibration with an optical tracker, simulated on the twin's probe (Table III's comparator).

Every error source of the tracker route is a switch of :class:`NWireSimConfig` with a default and
its own random stream (:data:`NWIRE_STREAMS`).

Design: ``docs/design/tracker_routes.md``, "The N-wire route".
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from brachycal.calibration.phantom.hand_eye import hand_eye
from brachycal.calibration.phantom.nwire import calibrate_nwire, wire_point_pairs
from brachycal.calibration.result import ImageCalibration
from brachycal.calibration.sequential import registration
from brachycal.data.formats.plus_files import PlusConfig, SegmentedFrame, Wire
from brachycal.errors import InputError, SolverError
from brachycal.imaging.pixels import DEFAULT_SPACING_M, image_points, pixels
from brachycal.model.ik import solve_ik
from brachycal.model.robot import Robot
from brachycal.planning.spec import SectorFOV
from brachycal.se3 import FloatArray, inverse, make_transform, transform_points
from brachycal.simulation.exact import workspace_frame
from brachycal.simulation.twin import Twin

MM = 1e-3
#: fCal 2.0 (PLUS's phantom definition), millimetres: three N patterns of (side, diagonal, side).
FCAL2_WIRES_MM = [
    (
        ("7:G1_g1", (30, 0, 20), (30, 40, 20)),
        ("8:L1_h1", (55, 0, 20), (35, 40, 20)),
        ("9:M1_m1", (60, 0, 20), (60, 40, 20)),
    ),
    (
        ("4:G3_g3", (30, 0, 10), (30, 40, 10)),
        ("5:H3_l3", (35, 0, 10), (55, 40, 10)),
        ("6:M3_m3", (60, 0, 10), (60, 40, 10)),
    ),
    (("1:H5_h5", (35, 0, 0), (35, 40, 0)), ("2:L5_i5", (55, 0, 0), (40, 40, 0)), ("3:M5_m5", (60, 0, 0), (60, 40, 0))),
]
FCAL2_LANDMARKS_MM = np.array(
    [
        [104.3, 5.0, 20.0],
        [104.3, 45.0, 20.0],
        [104.3, 45.0, 0.0],
        [104.3, -5.0, 0.0],
        [-34.3, 45.0, 15.0],
        [-34.3, -5.0, 20.0],
        [-34.3, -5.0, 0.0],
        [-34.3, 45.0, 0.0],
    ]
)
#: The pixel where the N-wire session's probe poses aim the phantom's centre (the wires' middle).
PHANTOM_CENTRE_PX = (540.0, 210.0)
#: Marker positions of a tracked body in its own frame (a typical 4-sphere tool), metres.
MARKER_BODY_M = np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [0.0, 0.04, 0.0], [0.03, 0.065, 0.01]])

#: The tracker route's random streams, one per error source (and the probe poses).
NWIRE_STREAMS = ("poses", "segmentation", "beam", "phantom", "landmarks", "field", "jitter", "latency", "encoder")
#: Mixed into the seed so that these streams never coincide with the twin's (same seed, other draws).
_STREAM_TAG = 0x4E57
#: Random Fourier modes of the tracker's error field.
_FIELD_MODES = 64


@dataclass(frozen=True)
class NWireSimConfig:
    """Settings of the simulated tracker-and-phantom route (see the module docstring for each source).

    Lengths in metres, angles in radians, times in seconds; SDs are per axis unless said "3D RMS".
    """

    seed: int = 0
    calibration_frames: int = 120
    validation_frames: int = 60
    hand_eye_poses: int = 12
    tracker_noise: bool = True
    tracker_accuracy_m: float = 0.25e-3  # 3D RMS per marker and frame (NDI Polaris Spectra)
    tracker_jitter_m: float = 0.10e-3  # 3D RMS, the part that changes from frame to frame
    tracker_field_length_m: float = 0.10
    tracker_frames: int = 20
    segmentation_noise: bool = True
    segmentation_sd_px: float = 0.5
    wire_beam_thickness: bool = True
    wire_beam_thickness_m: float = 0.6e-3
    phantom_tolerance: bool = True
    phantom_tolerance_sd_m: float = 0.1e-3
    landmark_noise: bool = True
    landmark_sd_m: float = 0.3e-3
    latency: bool = False
    latency_s: float = 0.010
    sweep_speed_m_s: float = 0.010
    sweep_rate_rad_s: float = 0.10

    def __post_init__(self) -> None:
        if not 0 <= self.tracker_jitter_m <= self.tracker_accuracy_m:
            raise InputError("tracker_jitter_m must be within [0, tracker_accuracy_m]: it is part of the accuracy")
        if self.tracker_frames < 1 or self.tracker_field_length_m <= 0:
            raise InputError("tracker_frames must be >= 1 and tracker_field_length_m > 0")

    def without_noise(self) -> NWireSimConfig:
        """The same set-up with every error source off (the robot's errors come from the twin)."""
        return replace(
            self,
            tracker_noise=False,
            segmentation_noise=False,
            wire_beam_thickness=False,
            phantom_tolerance=False,
            landmark_noise=False,
            latency=False,
        )

    @property
    def tracker_field_m(self) -> float:
        """3D RMS of the repeatable (volumetric) part of the tracker error: √(accuracy² − jitter²)."""
        return float(np.sqrt(self.tracker_accuracy_m**2 - self.tracker_jitter_m**2))


def _streams(seed: int) -> dict[str, np.random.Generator]:
    children = np.random.SeedSequence([seed, _STREAM_TAG]).spawn(len(NWIRE_STREAMS))
    return {name: np.random.default_rng(child) for name, child in zip(NWIRE_STREAMS, children, strict=True)}


class Tracker:
    """An optical tracker's readings of marker bodies: a fixed error field plus averaged jitter.

    The field ``b(p)`` (``p`` in the tracker's frame, metres) is a sum of random Fourier modes,
    ``b(p) = a Σ_k c_k cos(ω_k·p + φ_k)`` with ``c_k ~ N(0, I₃)``, ``ω_k ~ N(0, I₃ / L²)``, so its
    correlation falls as ``exp(−|Δp|² / 2L²)``, scaled to the configured 3D RMS over the volume.
    A reading averaged over ``n`` frames adds jitter of ``jitter / √n`` 3D RMS per marker.
    """

    def __init__(self, sim: NWireSimConfig, field_rng: np.random.Generator, jitter_rng: np.random.Generator) -> None:
        self.on = sim.tracker_noise
        self.jitter_rng = jitter_rng
        self.jitter_sd_m = sim.tracker_jitter_m / np.sqrt(3.0)  # per axis, one frame
        # Drawn whether or not the noise is on, so the stream's use does not depend on the switch.
        self.c = field_rng.normal(size=(_FIELD_MODES, 3))
        self.omega = field_rng.normal(scale=1.0 / sim.tracker_field_length_m, size=(_FIELD_MODES, 3))
        self.phase = field_rng.uniform(0.0, 2.0 * np.pi, size=_FIELD_MODES)
        # E|b|² = a² · modes · 3 · ½: the amplitude that gives the field's 3D RMS.
        self.amplitude = sim.tracker_field_m / np.sqrt(1.5 * _FIELD_MODES)

    def field(self, p_tracker: FloatArray) -> FloatArray:
        """``(N, 3)`` repeatable error of a marker read at ``p_tracker (N, 3)``, metres."""
        return self.amplitude * np.cos(p_tracker @ self.omega.T + self.phase) @ self.c

    def read(self, T_tracker_body: FloatArray, frames: int) -> FloatArray:
        """The tracker's pose of a marker body: markers read with error, averaged, pose by Kabsch."""
        markers = transform_points(T_tracker_body, MARKER_BODY_M)
        # The mean of ``frames`` independent jitters is one draw with SD / √frames.
        jitter = self.jitter_rng.normal(scale=self.jitter_sd_m / np.sqrt(frames), size=markers.shape)
        if not self.on:
            return T_tracker_body
        return registration.kabsch(MARKER_BODY_M, markers + self.field(markers) + jitter)


def fcal2_phantom(rng: np.random.Generator | None = None, tolerance_sd_m: float = 0.0) -> list[tuple[Wire, Wire, Wire]]:
    """The fCal 2.0 wires (metres, phantom frame); with ``rng``, each end moved by ``tolerance_sd_m`` per axis."""

    def end(p_mm: tuple[float, float, float]) -> FloatArray:
        shift = rng.normal(scale=tolerance_sd_m, size=3) if rng is not None else 0.0
        return np.array(p_mm) * MM + shift

    patterns = [[Wire(n, end(a), end(b)) for n, a, b in pattern] for pattern in FCAL2_WIRES_MM]
    return [(w1, w2, w3) for w1, w2, w3 in patterns]


def simulate_nwire(
    T_marker_image: FloatArray,
    spacing_m: FloatArray,
    size_px: tuple[int, int],
    sim: NWireSimConfig = NWireSimConfig(),
    tracker: Tracker | None = None,
) -> tuple[PlusConfig, list[SegmentedFrame], list[SegmentedFrame]]:
    """PLUS-like data of an N-wire session: the configuration (the phantom's CAD) and the frames.

    Args:
        T_marker_image: ``(4, 4)`` true image frame in the tracked probe body's frame.
        spacing_m: ``(2,)`` true pixel spacing, metres per pixel.
        size_px: image width and height.
        sim: the error sources.
        tracker: the tracker (default: a new one from ``sim``'s seed); the hand–eye session
            passes the same one so that both read the same error field.

    Returns:
        The configuration, ``sim.calibration_frames`` calibration frames and
        ``sim.validation_frames`` validation frames.
    """
    rng = _streams(sim.seed)
    tracker = tracker or Tracker(sim, rng["field"], rng["jitter"])
    cad = fcal2_phantom()
    # The physical phantom: drawn always (fixed use of the stream), applied if switched on.
    printed = fcal2_phantom(rng["phantom"], sim.phantom_tolerance_sd_m)
    landmark_shift = rng["phantom"].normal(scale=sim.phantom_tolerance_sd_m, size=FCAL2_LANDMARKS_MM.shape)
    physical = printed if sim.phantom_tolerance else cad
    T_tracker_phantom = make_transform(
        Rotation.from_euler("xyz", [5, -3, 20], degrees=True).as_matrix(), [0.3, -0.1, -1.2]
    )
    T_reference_phantom = make_transform(
        Rotation.from_euler("zx", [-90, 90], degrees=True).as_matrix(), [0.0157, -0.0254, -0.0408]
    )
    T_tracker_reference = T_tracker_phantom @ inverse(T_reference_phantom)
    # Phantom registration: the 8 printed landmarks touched with a stylus (in the reference frame),
    # registered to their CAD positions.
    landmarks_cad = FCAL2_LANDMARKS_MM * MM
    landmarks = landmarks_cad + (landmark_shift if sim.phantom_tolerance else 0.0)
    touch_error = rng["landmarks"].normal(scale=sim.landmark_sd_m, size=landmarks.shape)
    touched = transform_points(T_reference_phantom, landmarks) + (touch_error if sim.landmark_noise else 0.0)
    T_reference_phantom_est = registration.kabsch(landmarks_cad, touched)

    R_image = np.column_stack([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])  # u along x, depth down, normal along y
    fov = SectorFOV()
    spacing = np.asarray(spacing_m, dtype=float)
    frames: list[SegmentedFrame] = []
    static = not sim.latency
    while len(frames) < sim.calibration_frames + sim.validation_frames:
        tilt = Rotation.from_rotvec(rng["poses"].normal(scale=np.radians(6), size=3)).as_matrix()
        centre = np.array([0.045, rng["poses"].uniform(0.008, 0.032), 0.010]) + rng["poses"].normal(
            scale=[0.004, 0, 0.003]
        )
        R = R_image @ tilt
        origin = centre - R @ image_points(PHANTOM_CENTRE_PX, spacing)[0]
        T_phantom_image = make_transform(R, origin)
        T_image_phantom = inverse(T_phantom_image)
        # The pose is kept if every wire crosses the image inside the field of view (judged on the
        # CAD, so that the poses do not depend on the error switches).
        uv_cad = pixels([_crossing(*_ends(T_image_phantom, w), 0.0) for p in cad for w in p], spacing)
        if np.any(fov.margin_to_edge(uv_cad, spacing) < 0) or np.any(uv_cad < 0) or np.any(uv_cad >= size_px):
            continue
        ends = {w.name: _ends(T_image_phantom, w) for p in physical for w in p}
        elevation = rng["beam"].uniform(-0.5, 0.5, size=len(ends)) * sim.wire_beam_thickness_m
        noise = rng["segmentation"].normal(scale=sim.segmentation_sd_px, size=(len(ends), 2))
        points = {}
        for k, (name, (a, b)) in enumerate(ends.items()):
            hit = _crossing(a, b, elevation[k] if sim.wire_beam_thickness else 0.0)
            points[name] = pixels(hit, spacing)[0] + (noise[k] if sim.segmentation_noise else 0.0)
        T_tracker_probe = T_tracker_phantom @ T_phantom_image @ inverse(T_marker_image)
        lag = _lag(rng["latency"], sim)
        frames.append(
            SegmentedFrame(
                len(frames),
                True,
                points,
                tracker.read(T_tracker_probe @ lag, sim.tracker_frames if static else 1),
                tracker.read(T_tracker_reference, sim.tracker_frames if static else 1),
            )
        )
    config = PlusConfig(cad, {("Phantom", "Reference"): T_reference_phantom_est}, float(spacing.mean()))
    return config, frames[: sim.calibration_frames], frames[sim.calibration_frames :]


def _ends(T_image_phantom: FloatArray, wire: Wire) -> tuple[FloatArray, FloatArray]:
    """The wire's two ends in the image frame, ``(3,)`` each, metres."""
    a, b = transform_points(T_image_phantom, np.stack([wire.front_m, wire.back_m]))
    return a, b


def _crossing(a: FloatArray, b: FloatArray, z: float) -> FloatArray:
    """``(3,)`` point where the line through ``a`` and ``b`` (image frame) crosses the plane at height ``z``."""
    return a + ((z - a[2]) / (b[2] - a[2])) * (b - a)


def _lag(rng: np.random.Generator, sim: NWireSimConfig) -> FloatArray:
    """``(4, 4)`` motion of a sweeping probe during the tracker's time offset (identity for static captures)."""
    direction, axis = rng.normal(size=(2, 3))
    if not sim.latency:
        return np.eye(4)
    shift = sim.sweep_speed_m_s * sim.latency_s * direction / np.linalg.norm(direction)
    turn = sim.sweep_rate_rad_s * sim.latency_s * axis / np.linalg.norm(axis)
    return make_transform(Rotation.from_rotvec(turn).as_matrix(), shift)


@dataclass(frozen=True)
class TrackerRoute:
    """The tracker route's estimates: ``T_EL_Marker`` (hand–eye) and the image on the marker (N-wire)."""

    T_EL_marker: FloatArray
    image: ImageCalibration


def tracker_route(
    twin: Twin, sim: NWireSimConfig = NWireSimConfig(), nominal_spacing_m: float = DEFAULT_SPACING_M[0]
) -> TrackerRoute:
    """Simulate the N-wire session and the hand–eye calibration on the twin; return the estimates.

    Raises:
        SolverError: too few hand–eye poses are reachable.
    """
    truth = twin.truth
    rng = _streams(sim.seed)
    tracker = Tracker(sim, rng["field"], rng["jitter"])
    T_marker_image = inverse(T_PTIP_MARKER) @ truth.T_Ptip_I
    config, frames, _ = simulate_nwire(T_marker_image, truth.spacing_m, tuple(truth.size_px), sim, tracker)
    uv, p_marker, _ = wire_point_pairs(config, frames)
    result = calibrate_nwire(uv, p_marker, nominal_spacing_m)
    return TrackerRoute(
        _hand_eye_session(twin, sim, tracker, rng["encoder"]),
        ImageCalibration("nwire", result.T_Ptip_I, result.spacing_m),
    )


#: Where the probe's marker body sits on the probe tip frame (60 mm back along the shaft, 40 mm
#: to the side, turned 30° about the shaft).
T_PTIP_MARKER = make_transform(Rotation.from_euler("z", 30, degrees=True).as_matrix(), [0.04, 0.0, -0.06])
#: The tracker in the SDA10F's base_link terms (``T_tracker_base``): 1.5 m in front of the robot, facing it.
T_TRACKER_BASE = make_transform(Rotation.from_euler("xyz", [10, 170, -30], degrees=True).as_matrix(), [1.5, 0.2, 0.4])
#: The SDA10F's sample cube centre (``robots/sda10f.toml``), metres: the tracker of another robot
#: stands where it stands relative to this cube (:func:`tracker_pose`).
SDA10F_CUBE_CENTRE_M = (0.80, 0.10, 1.05)


def tracker_pose(robot: Robot) -> FloatArray:
    """``T_tracker_base (4, 4)`` for ``robot``: placed relative to its sample cube (workspace frame,
    :func:`~brachycal.simulation.exact.workspace_frame`) as :data:`T_TRACKER_BASE` is to the SDA10F's,
    so it faces the probe from the same distance; exactly :data:`T_TRACKER_BASE` on the SDA10F."""
    R_base_ws = workspace_frame(robot)
    centre = np.asarray(robot.rig.workspace.cube_centre_m, dtype=float)
    # T_sda_base_ws @ inv(T_base_ws), written out so that it is the identity to the bit on the SDA10F.
    T_sda_base = make_transform(R_base_ws.T, np.asarray(SDA10F_CUBE_CENTRE_M) - R_base_ws.T @ centre)
    return T_TRACKER_BASE @ T_sda_base


def _hand_eye_session(twin: Twin, sim: NWireSimConfig, tracker: Tracker, encoder: np.random.Generator) -> FloatArray:
    """Robot poses rotating the probe about three axes, read by the robot and seen by the tracker."""
    physical, nominal = twin.physical, twin.nominal
    flange, arm = nominal.rig.probe_flange, nominal.rig.probe_arm_indices
    T_tracker_base = tracker_pose(nominal)
    q_start = twin.true_samples_q[len(twin.true_samples_q) // 2]
    T_R_EL = physical.fk(flange, q_start)
    T_EL_marker = twin.truth.T_EL_Ptip @ T_PTIP_MARKER
    T_flange, T_marker = [], []
    for k in range(sim.hand_eye_poses):
        # Turn the flange about its own axes (x, y, z, then the other way round), as far as the arm allows.
        axis = np.eye(3)[k % 3] * (1 if (k // 3) % 2 == 0 else -1)
        for angle_deg in (20.0 + 5.0 * (k // 6), 12.0, 6.0):
            T_target = T_R_EL @ make_transform(
                Rotation.from_rotvec(np.radians(angle_deg) * axis).as_matrix(), np.zeros(3)
            )
            try:
                q_true = solve_ik(physical, flange, T_target, q_start, arm, margin=0.0, restarts=0)
                break
            except SolverError:  # this turn is out of reach: try a smaller one (input errors propagate)
                continue
        else:
            continue
        reading = encoder.normal(scale=twin.config.encoder_sd_rad, size=q_true.shape)
        q_read = q_true + (reading if twin.config.encoder_noise else 0.0)
        T_flange.append(nominal.fk(flange, q_read))
        seen = T_tracker_base @ physical.fk(flange, q_true) @ T_EL_marker
        T_marker.append(tracker.read(seen, sim.tracker_frames))
    if len(T_flange) < 3:
        raise SolverError(
            f"hand-eye session: only {len(T_flange)} of {sim.hand_eye_poses} probe turns are reachable (3 needed)"
        )
    pairs = [(i, j) for i in range(len(T_flange)) for j in range(i + 1, len(T_flange))]
    A = np.array([inverse(T_flange[i]) @ T_flange[j] for i, j in pairs])
    B = np.array([inverse(T_marker[i]) @ T_marker[j] for i, j in pairs])
    return hand_eye(A, B)


#: The tracker route's streams and its hand–eye session, for the other phantoms' routes
#: (:mod:`brachycal.studies.phantom_twin`: the same tracker field and the same robot turns).
nwire_streams = _streams
hand_eye_session = _hand_eye_session
