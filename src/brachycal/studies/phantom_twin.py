"""Multi-wedge and arbitrary-wire phantom calibrations with an optical tracker, simulated on the twin's probe.

Design: ``docs/design/tracker_routes.md``, "The multi-wedge and wire routes".
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from brachycal.calibration.phantom.features import PhantomResult
from brachycal.calibration.phantom.phantom_file import PhantomObservations
from brachycal.calibration.phantom.wedge import Face, WedgePhantom, calibrate_wedge, read_wedge_phantom
from brachycal.calibration.phantom.wire import WirePhantom, calibrate_wire, read_wire_phantom
from brachycal.calibration.result import ImageCalibration
from brachycal.calibration.sequential import registration
from brachycal.data.formats.plus_files import Wire
from brachycal.imaging.pixels import image_points, pixels
from brachycal.planning.spec import SectorFOV
from brachycal.se3 import FloatArray, inverse, make_transform, transform_points
from brachycal.simulation.twin import Twin
from brachycal.studies.nwire_twin import (
    T_PTIP_MARKER,
    NWireSimConfig,
    Tracker,
    TrackerRoute,
    hand_eye_session,
    nwire_streams,
)

#: Phantom methods simulated here, with their frames per session (module docstring).
FRAMES = {"wedge": 100, "wire": 120}
#: Their random streams (one per error source), tagged apart from the N-wire route's.
PHANTOM_STREAMS = ("poses", "segmentation", "beam", "phantom", "landmarks", "jitter")
_STREAM_TAG = {"wedge": 0x5745, "wire": 0x5749}
#: Where the poses aim the phantom's nominal centre (pixel) and that centre (phantom frame, metres).
AIM = {"wedge": ((540.0, 160.0), (0.0, 0.0, 0.0)), "wire": ((540.0, 210.0), (0.0, 0.0, -0.030))}
#: The faces' segmented part: from this far off the ridge to this far, metres (along u).
FACE_SEGMENT_M = (0.002, 0.010)
#: Half-width of a face over which its print tolerance turns it, metres.
FACE_HALF_WIDTH_M = 0.010


def _streams(seed: int, method: str) -> dict[str, np.random.Generator]:
    children = np.random.SeedSequence([seed, _STREAM_TAG[method]]).spawn(len(PHANTOM_STREAMS))
    return {name: np.random.default_rng(c) for name, c in zip(PHANTOM_STREAMS, children, strict=True)}


@dataclass(frozen=True)
class PhantomSession:
    """A simulated phantom session: the CAD (with the registration as the lab estimated it) and the data.

    ``T_phantom_image`` ``(F, 4, 4)`` (metres) and ``physical`` (the printed faces or wires, phantom
    frame) are the session's truth: what the images of :mod:`brachycal.studies.phantom_images` show.
    """

    phantom: WedgePhantom | WirePhantom
    observations: PhantomObservations
    T_phantom_image: FloatArray | None = None
    physical: list[Face] | list[Wire] | None = None


def _poses(rng: np.random.Generator, method: str, spacing: FloatArray) -> FloatArray:
    """One candidate ``T_phantom_image``: the nominal scan turned and moved as over the N-wire phantom."""
    R_image = np.column_stack([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])
    tilt = Rotation.from_rotvec(rng.normal(scale=np.radians(6), size=3)).as_matrix()
    aim_px, aim_m = AIM[method]
    centre = np.asarray(aim_m) + np.array([0.0, rng.uniform(-0.015, 0.015), 0.0]) + rng.normal(scale=[0.004, 0, 0.003])
    R = R_image @ tilt
    return make_transform(R, centre - R @ image_points(aim_px, spacing)[0])


def _face_line(face: Face, T_image_phantom: FloatArray, u_px: FloatArray, spacing: FloatArray, e: float):
    """``(2,)`` depth pixels ``v`` of the face at columns ``u_px (2,)`` on the plane of elevation ``e``."""
    n = T_image_phantom[:3, :3] @ face.normal
    c = n @ transform_points(T_image_phantom, face.point_m)
    return (c - n[0] * u_px * spacing[0] - n[2] * e) / (n[1] * spacing[1])


def _ridge_u(face: Face, ridge: FloatArray, T_image_phantom: FloatArray, spacing: FloatArray) -> float:
    """Column where the image plane crosses the face's ridge (the line through its point along ``ridge``)."""
    a = transform_points(T_image_phantom, face.point_m)
    b = T_image_phantom[:3, :3] @ ridge
    return float((a + (-a[2] / b[2]) * b)[0] / spacing[0])


def _printed_faces(cad: WedgePhantom, rng: np.random.Generator, sd_m: float) -> list[Face]:
    out = []
    for face in cad.faces:
        shift, turn = rng.normal(scale=sd_m), rng.normal(scale=sd_m / FACE_HALF_WIDTH_M, size=3)
        normal = Rotation.from_rotvec(turn).as_matrix() @ face.normal
        out.append(Face(face.name, face.wedge, face.point_m + shift * face.normal, normal / np.linalg.norm(normal)))
    return out


def _ridges(cad: WedgePhantom) -> dict[str, FloatArray]:
    """Each wedge's ridge direction: along the line where its first two faces meet."""
    ridges = {}
    for face in cad.faces:
        partner = next(f for f in cad.faces if f.wedge == face.wedge and f.name != face.name)
        r = np.cross(face.normal, partner.normal)
        ridges[face.name] = r / np.linalg.norm(r)
    return ridges


def simulate_phantom(
    method: str,
    T_marker_image: FloatArray,
    spacing_m: FloatArray,
    size_px: tuple[int, int],
    sim: NWireSimConfig | None = None,
    tracker: Tracker | None = None,
    frames: int | None = None,
) -> PhantomSession:
    """A tracked multi-wedge (``"wedge"``) or arbitrary-wire (``"wire"``) session (module docstring).

    Args:
        method: ``"wedge"`` or ``"wire"``.
        T_marker_image: ``(4, 4)`` true image frame in the probe's marker body, metres.
        spacing_m: ``(2,)`` true pixel spacing. size_px: image width and height.
        sim: the error sources (the N-wire twin's settings, default its defaults; its switches apply here too).
        tracker: the lab's tracker (default: the N-wire route's, from ``sim.seed``).
        frames: frames kept (default :data:`FRAMES`).
    """
    sim = sim or NWireSimConfig()
    rng = _streams(sim.seed, method)
    if tracker is None:
        base = nwire_streams(sim.seed)
        tracker = Tracker(sim, base["field"], rng["jitter"])
    frames = FRAMES[method] if frames is None else frames
    spacing = np.asarray(spacing_m, dtype=float)
    cad: WedgePhantom | WirePhantom = read_wedge_phantom() if method == "wedge" else read_wire_phantom()
    tol = sim.phantom_tolerance_sd_m
    # The physical phantom: drawn always (fixed use of the stream), applied if switched on.
    if isinstance(cad, WedgePhantom):
        printed_faces = _printed_faces(cad, rng["phantom"], tol)
        physical_faces = printed_faces if sim.phantom_tolerance else list(cad.faces)
        ridges = _ridges(cad)
        names = cad.names
    else:
        printed_wires = [
            Wire(
                w.name,
                w.front_m + rng["phantom"].normal(scale=tol, size=3),
                w.back_m + rng["phantom"].normal(scale=tol, size=3),
            )
            for w in cad.wires
        ]
        physical_wires = printed_wires if sim.phantom_tolerance else list(cad.wires)
        names = cad.names
    landmarks_cad = cad.geometry.landmarks_m
    landmark_shift = rng["phantom"].normal(scale=tol, size=landmarks_cad.shape)
    T_tracker_phantom = make_transform(
        Rotation.from_euler("xyz", [5, -3, 20], degrees=True).as_matrix(), [0.3, -0.1, -1.2]
    )
    T_reference_phantom = make_transform(
        Rotation.from_euler("zx", [-90, 90], degrees=True).as_matrix(), [0.0157, -0.0254, -0.0408]
    )
    T_tracker_reference = T_tracker_phantom @ inverse(T_reference_phantom)
    landmarks = landmarks_cad + (landmark_shift if sim.phantom_tolerance else 0.0)
    touch_error = rng["landmarks"].normal(scale=sim.landmark_sd_m, size=landmarks.shape)
    touched = transform_points(T_reference_phantom, landmarks) + (touch_error if sim.landmark_noise else 0.0)
    T_reference_phantom_est = registration.kabsch(landmarks_cad, touched)

    fov = SectorFOV()
    probe: list[FloatArray] = []
    reference: list[FloatArray] = []
    frame_of: list[int] = []
    feature: list[str] = []
    uv_all: list[FloatArray] = []
    poses: list[FloatArray] = []
    while len(probe) < frames:
        T_phantom_image = _poses(rng["poses"], method, spacing)
        T_image_phantom = inverse(T_phantom_image)
        if isinstance(cad, WedgePhantom):
            cad_uv, seen_uv = [], []
            noise = rng["segmentation"].normal(scale=sim.segmentation_sd_px, size=(len(cad.faces), 2))
            half = sim.wire_beam_thickness_m / 2 if sim.wire_beam_thickness else 0.0
            for k, (face, physical) in enumerate(zip(cad.faces, physical_faces, strict=True)):
                u_ridge = _ridge_u(face, ridges[face.name], T_image_phantom, spacing)
                # The face lies on the side of its ridge its normal leans to (a roof face tilts outwards).
                side = float(np.sign((T_image_phantom[:3, :3] @ face.normal)[0]))
                u = u_ridge + side * np.array(FACE_SEGMENT_M) / spacing[0]
                cad_uv.append(np.column_stack([u, _face_line(face, T_image_phantom, u, spacing, 0.0)]))
                v = np.minimum(
                    _face_line(physical, T_image_phantom, u, spacing, -half),
                    _face_line(physical, T_image_phantom, u, spacing, half),
                )
                seen_uv.append(np.column_stack([u, v + (noise[k] if sim.segmentation_noise else 0.0)]))
            check = np.concatenate(cad_uv)
        else:
            crossings_cad = [_crossing(T_image_phantom, w, 0.0) for w in cad.wires]
            check = pixels(np.array(crossings_cad), spacing)
            elevation = rng["beam"].uniform(-0.5, 0.5, size=len(cad.wires)) * sim.wire_beam_thickness_m
            noise = rng["segmentation"].normal(scale=sim.segmentation_sd_px, size=(len(cad.wires), 2))
            seen_uv = []
            for k, w in enumerate(physical_wires):
                hit = _crossing(T_image_phantom, w, elevation[k] if sim.wire_beam_thickness else 0.0)
                seen_uv.append(pixels(hit, spacing) + (noise[k] if sim.segmentation_noise else 0.0))
        if np.any(fov.margin_to_edge(check, spacing) < 0) or np.any(check < 0) or np.any(check >= size_px):
            continue
        T_tracker_probe = T_tracker_phantom @ T_phantom_image @ inverse(T_marker_image)
        poses.append(T_phantom_image)
        probe.append(tracker.read(T_tracker_probe, sim.tracker_frames))
        reference.append(tracker.read(T_tracker_reference, sim.tracker_frames))
        for name, uv in zip(names, seen_uv, strict=True):
            frame_of.append(len(probe) - 1)
            feature.append(name)
            uv_all.append(np.asarray(uv).reshape(-1, 2))
    observations = PhantomObservations(
        [str(k) for k in range(frames)],
        np.array(probe),
        np.array(reference),
        np.array(frame_of),
        feature,
        np.array(uv_all),
        list(range(2, len(feature) + 2)),
    )
    lab = replace(cad, geometry=replace(cad.geometry, T_reference_phantom=T_reference_phantom_est))
    printed: list[Face] | list[Wire] = physical_faces if isinstance(cad, WedgePhantom) else physical_wires
    return PhantomSession(lab, observations, np.array(poses), printed)


def _crossing(T_image_phantom: FloatArray, wire: Wire, z: float) -> FloatArray:
    """``(3,)`` where the wire crosses the plane at elevation ``z`` of the image frame."""
    a, b = transform_points(T_image_phantom, np.stack([wire.front_m, wire.back_m]))
    return a + ((z - a[2]) / (b[2] - a[2])) * (b - a)


def calibrate_session(session: PhantomSession) -> PhantomResult:
    """The phantom method's fit of a simulated session."""
    if isinstance(session.phantom, WedgePhantom):
        return calibrate_wedge(session.phantom, session.observations)
    return calibrate_wire(session.phantom, session.observations)


def phantom_route(
    twin: Twin,
    method: str,
    sim: NWireSimConfig | None = None,
    *,
    T_EL_marker: FloatArray | None = None,
    frames: int | None = None,
) -> TrackerRoute:
    """Simulate the phantom session on the twin's probe and calibrate it; with the hand–eye calibration.

    Args:
        twin: the simulated robot and probe.
        method: ``"wedge"`` or ``"wire"``.
        sim: the tracker and phantom error settings (the N-wire twin's).
        T_EL_marker: ``(4, 4)`` the hand–eye estimate to use (the N-wire route's, so that the routes
            differ only in their phantom); default: a hand–eye session of this route's own.
        frames: frames of the phantom session (default :data:`FRAMES`).

    Raises:
        SolverError: too few hand–eye poses are reachable, or the fit does not converge.
        DegenerateDataError: the simulated data cannot determine the fit.
    """
    truth = twin.truth
    sim = sim or NWireSimConfig()
    base = nwire_streams(sim.seed)
    rng = _streams(sim.seed, method)
    tracker = Tracker(sim, base["field"], rng["jitter"])
    T_marker_image = inverse(T_PTIP_MARKER) @ truth.T_Ptip_I
    session = simulate_phantom(method, T_marker_image, truth.spacing_m, tuple(truth.size_px), sim, tracker, frames)
    fit = calibrate_session(session)
    if T_EL_marker is None:
        T_EL_marker = hand_eye_session(twin, sim, tracker, base["encoder"])
    return TrackerRoute(T_EL_marker, ImageCalibration(method, fit.T_marker_image, fit.spacing_m))
