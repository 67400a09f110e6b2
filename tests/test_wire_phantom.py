"""The arbitrary-wire phantom method: exact recovery, ill-posed layouts, conditioning, the observations file."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from brachycal.calibration import calibrate_wire, calibrate_wire_files, read_wire_phantom, write_phantom_observations
from brachycal.calibration.phantom.features import SEGMENTATION_SD_PX
from brachycal.calibration.phantom.phantom_file import PhantomObservations
from brachycal.errors import ConditioningWarning, DegenerateDataError
from brachycal.imaging.pixels import image_points, pixels
from brachycal.se3 import inverse, make_transform, transform_points

# Exact data are recovered to rounding: the image→marker map agrees with the truth at the image's
# corners to 1e-9 m (a nanometre: far above rounding, far below any modelling slip).
EXACT_M = 1e-9
SPACING_M = np.array([0.19e-3, 0.185e-3])
CORNERS_PX = np.array([[0, 0], [1079, 0], [0, 719], [1079, 719]], dtype=float)
T_MARKER_IMAGE = make_transform(Rotation.from_euler("zyx", [-40, 15, 80], degrees=True).as_matrix(), [-0.02, 0.04, 0.1])


def scan_pose(rng: np.random.Generator, tilt_deg: float = 6.0) -> np.ndarray:
    R = (
        np.column_stack([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])
        @ Rotation.from_rotvec(rng.normal(scale=np.radians(tilt_deg), size=3)).as_matrix()
    )
    centre = np.array([0.0, rng.uniform(-0.015, 0.015), -0.03]) + rng.normal(scale=0.002, size=3)
    return make_transform(R, centre - R @ image_points([540.0, 210.0], SPACING_M)[0])


def exact_session(phantom, frames: int, seed: int = 0, noise_px: float = 0.0, tilt_deg: float = 6.0):
    """Tracked frames over the phantom, every wire's crossing (the reference body is the phantom frame)."""
    rng = np.random.default_rng(seed)
    T_tracker_phantom = make_transform(Rotation.from_euler("xyz", [5, -3, 20], degrees=True).as_matrix(), [0.3, 0, -1])
    probe, frame, feature, uv = [], [], [], []
    for f in range(frames):
        T_phantom_image = scan_pose(rng, tilt_deg)
        T_image_phantom = inverse(T_phantom_image)
        for wire in phantom.wires:
            a, b = transform_points(T_image_phantom, np.stack([wire.front_m, wire.back_m]))
            hit = a + (-a[2] / (b[2] - a[2])) * (b - a)
            uv.append(pixels(hit, SPACING_M) + rng.normal(scale=noise_px, size=(1, 2)))
            frame.append(f)
            feature.append(wire.name)
        probe.append(T_tracker_phantom @ T_phantom_image @ inverse(T_MARKER_IMAGE))
    return PhantomObservations(
        [str(f) for f in range(frames)],
        np.array(probe),
        np.repeat(T_tracker_phantom[None], frames, axis=0),
        np.array(frame),
        feature,
        np.array(uv),
        list(range(2, len(feature) + 2)),
    )


def corner_error_m(T_marker_image: np.ndarray, spacing_m: np.ndarray) -> float:
    got = transform_points(T_marker_image, image_points(CORNERS_PX, spacing_m))
    want = transform_points(T_MARKER_IMAGE, image_points(CORNERS_PX, SPACING_M))
    return float(np.max(np.linalg.norm(got - want, axis=1)))


def test_a_tracked_session_recovers_the_exact_calibration():
    phantom = read_wire_phantom()
    fit = calibrate_wire(phantom, exact_session(phantom, 12))
    assert corner_error_m(fit.T_marker_image, fit.spacing_m) < EXACT_M
    assert np.max(np.abs(fit.residuals_m)) < EXACT_M


def test_the_file_route_gives_the_in_memory_fit(tmp_path):
    phantom = read_wire_phantom()
    seen = exact_session(phantom, 12, noise_px=SEGMENTATION_SD_PX)
    path = write_phantom_observations(tmp_path / "wire.csv", "wire", seen)
    from_file, _, back = calibrate_wire_files(phantom.geometry.source, path)
    assert back.feature == seen.feature
    # The file holds 9 decimals of metres and 12 of quaternions: the fits agree far below a micrometre.
    assert np.max(np.abs(from_file.T_marker_image - calibrate_wire(phantom, seen).T_marker_image)) < 1e-7


def test_the_predicted_spread_bounds_the_spread_of_noisy_fits():
    # Segmentation noise moves a point in the image plane; its distance from the wire changes by
    # at most as much, so σ per equation makes the predicted SD an upper bound within a small factor.
    phantom = read_wire_phantom()
    errors, predicted = [], []
    for seed in range(12):
        fit = calibrate_wire(phantom, exact_session(phantom, 20, seed=seed, noise_px=SEGMENTATION_SD_PX))
        errors.append(corner_error_m(fit.T_marker_image, fit.spacing_m))
        predicted.append(fit.reach_sd_m)
    rms = float(np.sqrt(np.mean(np.square(errors))))
    # Corners lie up to ~120 mm out, beyond the 50 mm reach the prediction is made at.
    assert 0.3 * np.mean(predicted) < rms < 4.0 * np.mean(predicted)


def geometry(tmp_path, wires: list[tuple[tuple, tuple]]) -> str:
    text = 'format = "brachycal-phantom/1"\nkind = "wire"\n'
    for k, (a, b) in enumerate(wires):
        text += f'[[wire]]\nname = "W{k}"\nfrom_mm = {list(a)}\nto_mm = {list(b)}\n'
    path = tmp_path / "wires.toml"
    path.write_text(text)
    return str(path)


def test_parallel_wires_are_refused(tmp_path):
    wires = [((x, -30, z), (x, 30, z)) for x, z in ((-20, -20), (0, -30), (20, -25), (10, -40))]
    with pytest.raises(DegenerateDataError, match="parallel"):
        read_wire_phantom(geometry(tmp_path, wires))


def test_two_wires_are_refused(tmp_path):
    with pytest.raises(DegenerateDataError, match="at least 3"):
        read_wire_phantom(geometry(tmp_path, [((-20, -30, -20), (-10, 30, -30)), ((20, -30, -30), (0, 30, -20))]))


def test_coplanar_wires_are_refused_naming_the_free_turn(tmp_path):
    # All in the plane z = -30 mm: each image shows collinear points, the plane can turn about their line.
    wires = [((-20, -30, -30), (-10, 30, -30)), ((20, -30, -30), (0, 30, -30)), ((0, -30, -30), (15, 30, -30))]
    with pytest.raises(DegenerateDataError, match="turn about u"):
        read_wire_phantom(geometry(tmp_path, wires))


def test_too_few_frames_are_refused_and_barely_turned_poses_warn_or_refuse():
    phantom = read_wire_phantom()
    with pytest.raises(DegenerateDataError, match="1 frame"):
        calibrate_wire(phantom, exact_session(phantom, 1))
    # Three nearly identical poses with noise: the fit is determined per image but poorly; the
    # conditioning check must say so (warning) or refuse — never return silently.
    seen = exact_session(phantom, 3, seed=1, noise_px=3.0, tilt_deg=0.05)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            fit = calibrate_wire(phantom, seen)
        except DegenerateDataError as exc:
            assert "too poorly" in str(exc)
        else:
            assert fit.reach_sd_fit_m > 5e-4
            assert any(issubclass(w.category, ConditioningWarning) for w in caught)
