"""Registration (eq. 9): exact recovery, agreement between methods, planar and near-degenerate sets."""

from __future__ import annotations

import numpy as np
import pytest
from bands import assert_unbiased_variance
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from brachycal import InputError
from brachycal.calibration.sequential import registration
from brachycal.se3 import inverse, is_rigid, make_transform, transform_points

seeds = st.integers(0, 2**32 - 1)


def random_pose(rng: np.random.Generator) -> np.ndarray:
    return make_transform(Rotation.random(random_state=rng.integers(2**32)).as_matrix(), rng.normal(scale=0.2, size=3))


def point_set(rng: np.random.Generator, kind: str, n: int) -> np.ndarray:
    if kind == "general":
        return rng.normal(scale=0.03, size=(n, 3))
    if kind == "planar":  # image points: z = 0
        return np.column_stack([rng.uniform(0, 0.2, size=(n, 2)), np.zeros(n)])
    if kind == "thin":  # almost collinear: 1e-4 m spread across a 0.1 m line
        t = rng.uniform(0, 0.1, size=n)
        return np.column_stack([t, 1e-4 * rng.normal(size=n), np.zeros(n)])
    raise ValueError(kind)


@settings(max_examples=60, deadline=None)
@given(seeds, st.sampled_from(["general", "planar", "thin"]), st.integers(3, 70))
def test_kabsch_and_horn_recover_exact_transforms(seed, kind, n):
    rng = np.random.default_rng(seed)
    T_true = random_pose(rng)
    src = point_set(rng, kind, n)
    dst = transform_points(T_true, src)
    tolerance = 1e-9 if kind != "thin" else 1e-6  # rotation about the thin axis is ill-conditioned
    for method in (registration.kabsch, registration.horn):
        T = method(src, dst)
        assert is_rigid(T, tol=1e-12) and np.isclose(np.linalg.det(T[:3, :3]), 1.0)
        assert np.abs(transform_points(T, src) - dst).max() < 1e-9
        assert np.abs(T - T_true).max() < tolerance


def jittered_grid_pair(rng: np.random.Generator, kind: str, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(T_true, src, dst)``: ``n`` points of a jittered 5 cm grid (every point at least 3 cm from
    the others, so nearest-neighbour pairing is unambiguous after a few millimetres of initial
    error), planar or 3D, and their images under a random pose with 0.3 mm noise per coordinate."""
    T_true = random_pose(rng)
    if kind == "planar":
        cells = np.array([(i, j, 0) for i in range(9) for j in range(8)], dtype=float)
        jitter = rng.uniform(-0.2, 0.2, size=(n, 3)) * [1.0, 1.0, 0.0]
    else:
        cells = np.array([(i, j, k) for i in range(5) for j in range(5) for k in range(3)], dtype=float)
        jitter = rng.uniform(-0.2, 0.2, size=(n, 3))
    src = (cells[rng.permutation(len(cells))[:n]] + jitter) * 0.05
    dst = transform_points(T_true, src) + rng.normal(scale=3e-4, size=(n, 3))
    return T_true, src, dst


@settings(max_examples=60, deadline=None)
@given(seeds, st.sampled_from(["general", "planar"]), st.integers(3, 70))
def test_kabsch_horn_and_icp_agree_on_noisy_correspondences(seed, kind, n):
    rng = np.random.default_rng(seed)
    T_true, src, dst = jittered_grid_pair(rng, kind, n)
    T_k = registration.kabsch(src, dst)
    T_h = registration.horn(src, dst)
    T_init = T_true @ make_transform(Rotation.from_rotvec([0.01, -0.01, 0.005]).as_matrix(), [1e-3, 0, -1e-3])
    T_i, _, match = registration.icp(src, dst[::-1], T_init)  # ICP gets the targets unordered
    assert np.array_equal(match, np.arange(n)[::-1])
    assert np.abs(T_k - T_h).max() < 1e-9
    assert np.abs(T_k - T_i).max() < 1e-9


@settings(max_examples=25, deadline=None)
@given(seeds, st.sampled_from(["general", "planar"]), st.integers(5, 70))
def test_global_icp_agrees_with_kabsch_from_any_start(seed, kind, n):
    # The jittered grids and noise of jittered_grid_pair, but ICP is given a random prior (any rotation, a
    # translation of ~0.2 m): its 48 principal-axes starts find the fit Kabsch finds with the pairs.
    rng = np.random.default_rng(seed)
    _, src, dst = jittered_grid_pair(rng, kind, n)
    result = registration.icp_global(src, dst[::-1], random_pose(rng), tie_m=np.sqrt(3) * 3e-4)
    assert np.array_equal(result.match, np.arange(n)[::-1])
    assert np.abs(result.T - registration.kabsch(src, dst)).max() < 1e-9


@settings(max_examples=40, deadline=None)
@given(seeds, st.integers(3, 40))
def test_kabsch_matches_scipy_align_vectors(seed, n):
    # An independent second computation of the optimal rotation.
    rng = np.random.default_rng(seed)
    src = point_set(rng, "general", n)
    dst = transform_points(random_pose(rng), src) + rng.normal(scale=1e-3, size=(n, 3))
    T = registration.kabsch(src, dst)
    R_scipy, _ = Rotation.align_vectors(dst - dst.mean(0), src - src.mean(0))
    assert np.abs(T[:3, :3] - R_scipy.as_matrix()).max() < 1e-9


def test_reflection_is_never_returned():
    # Mirror-image targets: the best orthogonal fit is a reflection; Kabsch must return a rotation.
    rng = np.random.default_rng(3)
    src = rng.normal(size=(10, 3))
    dst = src * [1.0, 1.0, -1.0]
    for method in (registration.kabsch, registration.horn):
        assert np.isclose(np.linalg.det(method(src, dst)[:3, :3]), 1.0)


def test_similarity_of_a_mirror_image_is_the_best_proper_fit():
    # Mirror-image targets scaled by 1.1: the best similarity with a reflection would fit them exactly;
    # the best proper one has Kabsch's rotation and, for it, the least-squares scale Σ bᵢ·R aᵢ / Σ |aᵢ|²
    # (centred points a, b).
    rng = np.random.default_rng(3)
    src = rng.normal(size=(10, 3))
    dst = 1.1 * src * [1.0, 1.0, -1.0] + rng.normal(scale=0.01, size=(10, 3))
    T, scale = registration.similarity(src, dst)
    R = T[:3, :3]
    assert np.isclose(np.linalg.det(R), 1.0)
    assert np.abs(R - registration.kabsch(src, dst)[:3, :3]).max() < 1e-12
    a, b = src - src.mean(axis=0), dst - dst.mean(axis=0)
    assert scale == pytest.approx(np.sum(b * (a @ R.T)) / np.sum(a**2), rel=1e-12)
    assert np.abs(T[:3, 3] - (dst.mean(axis=0) - scale * R @ src.mean(axis=0))).max() < 1e-12


@pytest.mark.parametrize(("model", "n"), [("rigid", 3), ("rigid", 5), ("similarity", 4), ("uv", 4), ("uv", 8)])
def test_fit_noise_estimate_is_unbiased_with_its_degrees_of_freedom(model, n):
    # Isotropic noise σ per coordinate on the targets: the residual sum of squares of the fit is σ² χ²
    # with 3N − p degrees of freedom (p = 6 + the scale factors), to first order in σ (here 1e-7
    # relative), so σ̂² = RSS / (3N − p) is unbiased even for a few points.
    rng = np.random.default_rng(n)
    T_true, sigma, draws = random_pose(rng), 1e-4, 300
    src = point_set(rng, "general" if model != "uv" else "planar", n)
    scale = 1.0 if model == "rigid" else 1.02
    ratios = []
    for _ in range(draws):
        dst = transform_points(T_true, scale * src) + rng.normal(scale=sigma, size=src.shape)
        if model == "rigid":
            T, factors = registration.kabsch(src, dst), np.ones(3)
        elif model == "similarity":
            T, k = registration.similarity(src, dst)
            factors = np.full(3, k)
        else:
            T, spacing = registration.scaled_uv(src[:, :2], dst, [1.0, 1.0])
            factors = np.append(spacing, 1.0)
        u = registration.fit_uncertainty(src, dst, T, model=model, scale=factors)
        assert u.dof == 3 * n - 6 - registration.SCALE_MODELS[model]
        ratios.append((u.noise_sd_m / sigma) ** 2)
    assert_unbiased_variance(ratios, 3 * n - 6 - registration.SCALE_MODELS[model])


@settings(max_examples=40, deadline=None)
@given(seeds, st.floats(0.9, 1.1), st.sampled_from(["general", "planar"]))
def test_similarity_recovers_scale(seed, scale, kind):
    rng = np.random.default_rng(seed)
    T_true = random_pose(rng)
    src = point_set(rng, kind, 20)
    dst = transform_points(T_true, scale * src)
    T, s = registration.similarity(src, dst)
    assert abs(s - scale) < 1e-12
    assert np.abs(T - T_true).max() < 1e-9


@settings(max_examples=30, deadline=None)
@given(seeds, st.floats(0.95, 1.05), st.floats(0.95, 1.05))
def test_scaled_uv_recovers_each_pixel_spacing(seed, k_u, k_v):
    rng = np.random.default_rng(seed)
    T_true = random_pose(rng)
    nominal = np.array([0.19e-3, 0.19e-3])
    uv = rng.uniform([0, 0], [1080, 720], size=(30, 2))
    true_spacing = nominal * [k_u, k_v]
    dst = transform_points(T_true, np.column_stack([uv * true_spacing, np.zeros(30)]))
    T, spacing = registration.scaled_uv(uv, dst, nominal)
    assert np.abs(spacing - true_spacing).max() < 1e-15
    assert np.abs(T - T_true).max() < 1e-9


@settings(max_examples=20, deadline=None)
@given(seeds)
def test_scaled_uv_stops_at_the_least_squares_minimum_of_noisy_data(seed):
    # At the minimiser the cost's gradient Jᵀr vanishes: each parameter's column of J is orthogonal to
    # the residual. Measured as the cosine between them; rounding leaves ~1e-13 (worst 2e-11 over 60
    # seeds); a solve stopped early, or one on a finite-difference Jacobian (SciPy's, before), leaves
    # 1e-9 and more.
    rng = np.random.default_rng(seed)
    T_true = random_pose(rng)
    nominal = np.array([0.19e-3, 0.19e-3])
    uv = rng.uniform([0, 0], [1080, 720], size=(40, 2))
    p_image = np.column_stack([uv * nominal * [1.03, 0.97], np.zeros(40)])
    dst = transform_points(T_true, p_image) + rng.normal(scale=3e-4, size=(40, 3))
    T, spacing = registration.scaled_uv(uv, dst, nominal)
    src = np.column_stack([uv * nominal, np.zeros(40)])
    factors = np.append(spacing / nominal, 1.0)
    J = registration._jacobian("uv", T[:3, :3], factors, src)
    r = ((src * factors) @ T[:3, :3].T + T[:3, 3] - dst).ravel()
    cosine = np.abs(J.T @ r) / (np.linalg.norm(J, axis=0) * np.linalg.norm(r))
    assert cosine.max() < 1e-9


def test_icp_with_correct_correspondences_is_kabsch():
    rng = np.random.default_rng(5)
    src = point_set(rng, "planar", 64)
    T_true = random_pose(rng)
    dst = transform_points(T_true, src) + rng.normal(scale=5e-4, size=src.shape)
    T_icp, iterations, _ = registration.icp(src, dst, T_true)
    assert iterations >= 1
    assert np.abs(T_icp - registration.kabsch(src, dst)).max() < 1e-12


def test_degenerate_point_sets_are_refused():
    with pytest.raises(InputError, match="at least 3"):
        registration.kabsch(np.zeros((2, 3)), np.zeros((2, 3)))
    line = np.outer(np.linspace(0, 1, 5), [1.0, 2.0, 0.0])
    with pytest.raises(InputError, match="collinear"):
        registration.horn(line, line)
    with pytest.raises(InputError, match="NaN"):
        registration.kabsch(np.full((4, 3), np.nan), np.zeros((4, 3)))
    with pytest.raises(InputError, match="differ in shape"):
        registration.kabsch(np.eye(3), np.eye(4)[:, :3])


def test_results_are_proper_rigid_transforms():
    rng = np.random.default_rng(6)
    src = point_set(rng, "planar", 12)
    dst = rng.normal(size=(12, 3))  # unrelated points: still a proper rotation
    for T in (registration.kabsch(src, dst), registration.horn(src, dst), registration.similarity(src, dst)[0]):
        assert is_rigid(T, tol=1e-12)
        assert np.allclose(inverse(T) @ T, np.eye(4))
