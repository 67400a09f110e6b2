"""N-wire calibration with an optical tracker, simulated on the twin's probe (Table III's comparator).

The tracker route, as a lab with an optical tracker would run it on this robot:

1. N-wire: the twin's probe (its true image geometry and pixel spacing, water's sound speed
   included) images an fCal 2.0 phantom in the tank from varied poses; the tracker follows a
   marker body on the probe and one on the phantom's reference. :mod:`brachycal.calibration.nwire`
   gives ``T_Marker_I``.
2. Hand–eye: the robot moves the probe through rotations about three axes while the tracker
   follows the marker; :func:`brachycal.calibration.hand_eye.hand_eye` gives ``T_EL_Marker``.

The whole-system chain is then ``T_R_EL @ T_EL_Marker @ T_Marker_I``, judged by the same
end-to-end targeting error as the mechanism-image fusion method on the same simulated robot.
Errors, each switchable: segmentation noise on every wire intersection (0.5 px SD), tracker
noise of 0.25 mm RMS per marker on 4-marker bodies (poses fitted by Kabsch), the
phantom-to-reference registration from 8 landmarks touched with a tracked stylus (0.3 mm SD per
landmark), and, through the twin, the robot's own geometry error and encoder noise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from brachycal.calibration import registration
from brachycal.calibration.hand_eye import hand_eye
from brachycal.calibration.image_to_probe import ImageCalibration
from brachycal.calibration.nwire import calibrate_nwire, wire_point_pairs
from brachycal.data.plus_files import PlusConfig, SegmentedFrame, Wire
from brachycal.errors import InputError
from brachycal.model.ik import solve_ik
from brachycal.model.names import LEFT_FLANGE
from brachycal.planning.spec import SectorFOV
from brachycal.se3 import FloatArray, inverse, make_transform, transform_points
from brachycal.simulation.exact import LEFT
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
#: Marker positions of a tracked body in its own frame (a typical 4-sphere tool), metres.
MARKER_BODY_M = np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [0.0, 0.04, 0.0], [0.03, 0.065, 0.01]])


@dataclass(frozen=True)
class NWireSimConfig:
    """Settings of the simulated tracker-and-phantom calibration."""

    seed: int = 0
    calibration_frames: int = 120
    validation_frames: int = 60
    segmentation_sd_px: float = 0.5
    tracker_marker_sd_m: float = 0.25e-3
    landmark_sd_m: float = 0.3e-3
    hand_eye_poses: int = 12

    def without_noise(self) -> NWireSimConfig:
        return NWireSimConfig(
            self.seed, self.calibration_frames, self.validation_frames, 0.0, 0.0, 0.0, self.hand_eye_poses
        )


#: Where the probe's marker body sits on the probe tip frame (60 mm back along the shaft, 40 mm
#: to the side, turned 30° about the shaft).
T_PTIP_MARKER = make_transform(Rotation.from_euler("z", 30, degrees=True).as_matrix(), [0.04, 0.0, -0.06])


def fcal2_phantom() -> list[tuple[Wire, Wire, Wire]]:
    return [tuple(Wire(n, np.array(a) * MM, np.array(b) * MM) for n, a, b in pattern) for pattern in FCAL2_WIRES_MM]


def _tracked(T: FloatArray, rng: np.random.Generator, sd: float) -> FloatArray:
    """A tracker's pose of a marker body: markers seen with noise, pose by Kabsch."""
    if sd <= 0:
        return T
    seen = transform_points(T, MARKER_BODY_M) + rng.normal(scale=sd, size=MARKER_BODY_M.shape)
    return registration.kabsch(MARKER_BODY_M, seen)


def simulate_nwire(
    T_marker_image: FloatArray, spacing_m: FloatArray, size_px: tuple[int, int], sim: NWireSimConfig = NWireSimConfig()
) -> tuple[PlusConfig, list[SegmentedFrame], list[SegmentedFrame]]:
    """PLUS-like data of an N-wire session: the (estimated) configuration and the frames.

    Args:
        T_marker_image: ``(4, 4)`` true image frame in the tracked probe body's frame.
        spacing_m: ``(2,)`` true pixel spacing.
        size_px: image width and height.
        sim: noise settings.
    """
    rng = np.random.default_rng(np.random.SeedSequence(sim.seed).spawn(1)[0])
    patterns = fcal2_phantom()
    T_tracker_phantom = make_transform(
        Rotation.from_euler("xyz", [5, -3, 20], degrees=True).as_matrix(), [0.3, -0.1, -1.2]
    )
    T_reference_phantom = make_transform(
        Rotation.from_euler("zx", [-90, 90], degrees=True).as_matrix(), [0.0157, -0.0254, -0.0408]
    )
    T_tracker_reference = T_tracker_phantom @ inverse(T_reference_phantom)
    # Phantom registration: 8 landmarks touched with a stylus, in the reference frame.
    landmarks = FCAL2_LANDMARKS_MM * MM
    touched = transform_points(T_reference_phantom, landmarks) + rng.normal(
        scale=sim.landmark_sd_m, size=landmarks.shape
    )
    T_reference_phantom_est = registration.kabsch(landmarks, touched) if sim.landmark_sd_m > 0 else T_reference_phantom

    R_image = np.column_stack([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])  # u along x, depth down, normal along y
    fov = SectorFOV()
    spacing = np.asarray(spacing_m, dtype=float)
    frames: list[SegmentedFrame] = []
    while len(frames) < sim.calibration_frames + sim.validation_frames:
        tilt = Rotation.from_rotvec(rng.normal(scale=np.radians(6), size=3)).as_matrix()
        centre = np.array([0.045, rng.uniform(0.008, 0.032), 0.010]) + rng.normal(scale=[0.004, 0, 0.003])
        R = R_image @ tilt
        target_px = np.array([540.0, 210.0])
        origin = centre - R @ [target_px[0] * spacing[0], target_px[1] * spacing[1], 0.0]
        T_phantom_image = make_transform(R, origin)
        T_image_phantom = inverse(T_phantom_image)
        points = {}
        for pattern in patterns:
            for wire in pattern:
                a, b = transform_points(T_image_phantom, np.stack([wire.front_m, wire.back_m]))
                hit = a + (-a[2] / (b[2] - a[2])) * (b - a)
                points[wire.name] = hit[:2] / spacing + rng.normal(scale=sim.segmentation_sd_px, size=2)
        uv = np.array(list(points.values()))
        if np.any(fov.margin_to_edge(uv, spacing) < 0) or np.any(uv < 0) or np.any(uv >= size_px):
            continue
        T_tracker_probe = T_tracker_phantom @ T_phantom_image @ inverse(T_marker_image)
        frames.append(
            SegmentedFrame(
                len(frames),
                True,
                points,
                _tracked(T_tracker_probe, rng, sim.tracker_marker_sd_m),
                _tracked(T_tracker_reference, rng, sim.tracker_marker_sd_m),
            )
        )
    config = PlusConfig(patterns, {("Phantom", "Reference"): T_reference_phantom_est}, float(spacing.mean()))
    return config, frames[: sim.calibration_frames], frames[sim.calibration_frames :]


@dataclass(frozen=True)
class TrackerRoute:
    """The tracker route's estimates: ``T_EL_Marker`` (hand–eye) and the image on the marker (N-wire)."""

    T_EL_marker: FloatArray
    image: ImageCalibration


def tracker_route(
    twin: Twin, sim: NWireSimConfig = NWireSimConfig(), nominal_spacing_m: float = 0.19e-3
) -> TrackerRoute:
    """Simulate the N-wire session and the hand–eye calibration on the twin; return the estimates."""
    truth = twin.truth
    T_marker_image = inverse(T_PTIP_MARKER) @ truth.T_Ptip_I
    config, frames, _ = simulate_nwire(T_marker_image, truth.spacing_m, tuple(truth.size_px), sim)
    uv, p_marker, _ = wire_point_pairs(config, frames)
    result = calibrate_nwire(uv, p_marker, nominal_spacing_m)
    return TrackerRoute(_hand_eye_session(twin, sim), ImageCalibration("nwire", result.T_probe_image, result.spacing_m))


def _hand_eye_session(twin: Twin, sim: NWireSimConfig) -> FloatArray:
    """Robot poses rotating the probe about three axes, read by the robot and seen by the tracker."""
    rng = np.random.default_rng(np.random.SeedSequence(sim.seed).spawn(2)[1])
    physical, nominal = twin.physical, twin.nominal
    q_start = twin.true_samples_q[len(twin.true_samples_q) // 2]
    T_R_EL = physical.fk(LEFT_FLANGE, q_start)
    T_EL_marker = twin.truth.T_EL_Ptip @ T_PTIP_MARKER
    T_tracker_base = make_transform(
        Rotation.from_euler("xyz", [10, 170, -30], degrees=True).as_matrix(), [1.5, 0.2, 0.4]
    )
    T_flange, T_marker = [], []
    for k in range(sim.hand_eye_poses):
        # Turn the flange about its own axes (x, y, z, then the other way round), as far as the arm allows.
        axis = np.eye(3)[k % 3] * (1 if (k // 3) % 2 == 0 else -1)
        for angle_deg in (20.0 + 5.0 * (k // 6), 12.0, 6.0):
            T_target = T_R_EL @ make_transform(
                Rotation.from_rotvec(np.radians(angle_deg) * axis).as_matrix(), np.zeros(3)
            )
            try:
                q_true = solve_ik(physical, LEFT_FLANGE, T_target, q_start, LEFT, margin=0.0, restarts=0)
                break
            except InputError:
                continue
        else:
            continue
        q_read = q_true + (
            rng.normal(scale=twin.config.encoder_sd_rad, size=q_true.shape) if twin.config.encoder_noise else 0.0
        )
        T_flange.append(nominal.fk(LEFT_FLANGE, q_read))
        seen = T_tracker_base @ physical.fk(LEFT_FLANGE, q_true) @ T_EL_marker
        T_marker.append(_tracked(seen, rng, sim.tracker_marker_sd_m))
    pairs = [(i, j) for i in range(len(T_flange)) for j in range(i + 1, len(T_flange))]
    A = np.array([inverse(T_flange[i]) @ T_flange[j] for i, j in pairs])
    B = np.array([inverse(T_marker[i]) @ T_marker[j] for i, j in pairs])
    return hand_eye(A, B)
