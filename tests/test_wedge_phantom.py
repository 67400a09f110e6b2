"""The multi-wedge phantom method: exact recovery, the closed-form single-image pose, refusals, error propagation."""

from __future__ import annotations

import textwrap

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from brachycal.calibration import (
    calibrate_wedge,
    calibrate_wedge_files,
    image_pose_in_phantom,
    read_phantom_observations,
    read_wedge_phantom,
    write_phantom_observations,
)
from brachycal.calibration.phantom.features import SEGMENTATION_SD_PX
from brachycal.calibration.phantom.phantom_file import PhantomObservations
from brachycal.calibration.phantom.wedge import lines_in_image
from brachycal.errors import DegenerateDataError, InputError
from brachycal.imaging.pixels import image_points
from brachycal.se3 import inverse, make_transform, transform_points

# Exact data are recovered to rounding: the map from the image to the marker body agrees with the
# truth at the image's corners to 1e-9 m (a nanometre; rounding of the ~1e-16 relative kind is
# far below it, any modelling slip far above).
EXACT_M = 1e-9
SPACING_M = np.array([0.19e-3, 0.205e-3])
CORNERS_PX = np.array([[0, 0], [1079, 0], [0, 719], [1079, 719]], dtype=float)
T_MARKER_IMAGE = make_transform(
    Rotation.from_euler("xyz", [100, -20, 35], degrees=True).as_matrix(), [0.03, -0.05, 0.11]
)


def scan_pose(rng: np.random.Generator) -> np.ndarray:
    """A ``T_phantom_image`` of the nominal scan (depth along −z, normal along y), turned and moved."""
    R = (
        np.column_stack([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])
        @ Rotation.from_rotvec(rng.normal(scale=np.radians(6), size=3)).as_matrix()
    )
    centre = np.array([0.0, rng.uniform(-0.01, 0.01), 0.0]) + rng.normal(scale=0.002, size=3)
    return make_transform(R, centre - R @ image_points([540.0, 160.0], SPACING_M)[0])


def exact_session(phantom, frames: int, seed: int = 0, noise_px: float = 0.0) -> PhantomObservations:
    """Tracked frames over the phantom (the reference body is the phantom frame), every face's line by two ends."""
    rng = np.random.default_rng(seed)
    T_tracker_phantom = make_transform(Rotation.from_euler("xyz", [5, -3, 20], degrees=True).as_matrix(), [0.3, 0, -1])
    probe, frame, feature, uv = [], [], [], []
    for f in range(frames):
        T_phantom_image = scan_pose(rng)
        u = np.array([[380.0, 450.0], [470.0, 520.0], [560.0, 620.0], [650.0, 700.0], [300.0, 360.0], [740.0, 800.0]])
        lines = lines_in_image(phantom, T_phantom_image, SPACING_M, u[: len(phantom.faces)])
        lines[:, :, 1] += rng.normal(scale=noise_px, size=lines.shape[:2])
        probe.append(T_tracker_phantom @ T_phantom_image @ inverse(T_MARKER_IMAGE))
        frame += [f] * len(phantom.faces)
        feature += phantom.names
        uv += list(lines)
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
    phantom = read_wedge_phantom()
    fit = calibrate_wedge(phantom, exact_session(phantom, 8))
    assert corner_error_m(fit.T_marker_image, fit.spacing_m) < EXACT_M
    assert np.max(np.abs(fit.residuals_m)) < EXACT_M
    assert fit.frames == 8 and fit.observations == 8 * len(phantom.faces)


def test_one_image_gives_the_image_planes_pose_and_spacings_in_closed_form():
    phantom = read_wedge_phantom()
    T_phantom_image = scan_pose(np.random.default_rng(3))
    u = np.array([[380.0, 450.0], [470.0, 520.0], [560.0, 620.0], [650.0, 700.0], [300.0, 360.0], [740.0, 800.0]])
    lines = lines_in_image(phantom, T_phantom_image, SPACING_M, u)
    T, spacing = image_pose_in_phantom(phantom, phantom.names, lines)
    got = transform_points(T, image_points(CORNERS_PX, spacing))
    want = transform_points(T_phantom_image, image_points(CORNERS_PX, SPACING_M))
    assert np.max(np.linalg.norm(got - want, axis=1)) < EXACT_M
    with pytest.raises(DegenerateDataError, match="at least 5"):
        image_pose_in_phantom(phantom, phantom.names[:4], lines[:4])


def test_the_observations_file_round_trips_and_gives_the_same_fit(tmp_path):
    phantom = read_wedge_phantom()
    seen = exact_session(phantom, 5, noise_px=0.5)
    path = write_phantom_observations(tmp_path / "wedge.csv", "multi-wedge", seen)
    back = read_phantom_observations(path, "multi-wedge", phantom.names)
    assert back.frames == seen.frames and back.feature == seen.feature
    # Written with 9 decimals (1 nm) and 12 for quaternions: the fits agree to well under a micrometre.
    from_file, _, _ = calibrate_wedge_files(phantom.geometry.source, path)
    in_memory = calibrate_wedge(phantom, seen)
    assert np.max(np.abs(from_file.T_marker_image - in_memory.T_marker_image)) < 1e-7


def test_the_predicted_spread_matches_the_spread_of_noisy_fits():
    # The refusal threshold rests on Cov = σ² (JᵀJ)⁻¹: check it against Monte Carlo. Segmentation
    # noise moves a line end along v; its distance from the plane changes by that times |n·v| ≤ 1,
    # so the prediction (σ per equation) bounds the spread from above, within a small factor.
    phantom = read_wedge_phantom()
    errors, predicted = [], []
    for seed in range(12):
        fit = calibrate_wedge(phantom, exact_session(phantom, 20, seed=seed, noise_px=SEGMENTATION_SD_PX))
        errors.append(corner_error_m(fit.T_marker_image, fit.spacing_m))
        predicted.append(fit.reach_sd_m)
    rms = float(np.sqrt(np.mean(np.square(errors))))
    # Corners lie further out than the 50 mm reach (up to ~120 mm): up to ~3x the reach's SD.
    assert 0.5 * np.mean(predicted) < rms < 4.0 * np.mean(predicted)


def write_geometry(path, wedges: str) -> None:
    path.write_text('format = "brachycal-phantom/1"\nkind = "multi-wedge"\n' + textwrap.dedent(wedges))


def test_one_wedge_is_refused(tmp_path):
    write_geometry(
        tmp_path / "one.toml",
        """
        [[wedge]]
        name = "A"
        [[wedge.face]]
        name = "A1"
        point_mm = [0, 0, 0]
        normal = [-0.5, 0, 0.866]
        [[wedge.face]]
        name = "A2"
        point_mm = [0, 0, 0]
        normal = [0.5, 0, 0.866]
        """,
    )
    with pytest.raises(DegenerateDataError, match="1 wedge"):
        read_wedge_phantom(tmp_path / "one.toml")


def test_wedges_whose_ridges_all_run_along_the_scan_are_refused(tmp_path):
    # Every normal lies in the x-z plane: the image plane can slide along y unseen.
    faces = "".join(
        f"""
        [[wedge]]
        name = "{w}"
        [[wedge.face]]
        name = "{w}1"
        point_mm = [{x}, 0, 0]
        normal = [-0.5, 0, 0.866]
        [[wedge.face]]
        name = "{w}2"
        point_mm = [{x}, 0, 0]
        normal = [0.5, 0, 0.866]
        """
        for w, x in (("A", -30), ("B", 0), ("C", 30))
    )
    write_geometry(tmp_path / "parallel.toml", faces)
    with pytest.raises(DegenerateDataError, match="position along its normal"):
        read_wedge_phantom(tmp_path / "parallel.toml")


def test_too_few_frames_and_a_wire_file_are_refused():
    phantom = read_wedge_phantom()
    with pytest.raises(DegenerateDataError, match="2 frame"):
        calibrate_wedge(phantom, exact_session(phantom, 2))
    with pytest.raises(InputError, match="not a 'multi-wedge'"):
        read_wedge_phantom(phantom.geometry.source.replace("multi_wedge", "arbitrary_wire"))
