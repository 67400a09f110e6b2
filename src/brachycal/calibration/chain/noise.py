"""Noise levels of the chain's residual groups (touches, axes moves, images): estimated from the
residuals with the degrees-of-freedom correction, and each group's share left to the session's
noise once a stated robot accuracy is taken out (module docstring of :mod:`brachycal.calibration.chain`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from brachycal.calibration.chain.conditioning import RCOND_LIMIT
from brachycal.se3 import FloatArray

#: Starting noise levels (metres per coordinate) of the residual groups; also the level assumed
#: for a group with too few residual degrees of freedom to estimate its own.
INITIAL_SIGMA = {"touch": 1e-4, "axes": 1e-4, "image": 3e-4}
GROUPS = ("touch", "axes", "image")
#: Fewest residual degrees of freedom ν from which a group's noise level is estimated: the
#: relative SD of the estimate is about 1/√(2ν), 25 % at ν = 8.
MIN_NOISE_DOF = 8.0
#: One micrometre: below anything this set-up resolves (encoder noise alone is ~20 µm at 1 m). A
#: group's noise level is not taken below it (it weights the group), and a group whose residual
#: scale is at it is reported as below resolution, not as a measured noise level.
RESOLUTION_M = 1e-6


@dataclass(frozen=True)
class NoiseLevel:
    """A residual group's noise level and where it comes from.

    Attributes:
        sd_m: noise SD per coordinate, metres (the weight the group gets).
        dof: residual degrees of freedom of the group (its rows minus its leverages).
        source: ``"residuals"`` (estimated from them), ``"assumed"`` (too few degrees of freedom;
            see ``note``) or ``"below resolution"`` (the residuals are under :data:`RESOLUTION_M`).
        note: one line a person can read.
    """

    sd_m: float
    dof: float
    source: str
    note: str


#: Reciprocal condition number (of the equilibrated ``J``) above which :func:`leverages` uses the
#: Cholesky factor of ``JᵀJ``: its relative error, ~ε/rcond², is then below 1e-9 (the chain's
#: sessions measure 7e-3 and up), and every singular value is far above the SVD's cut
#: (:data:`RCOND_LIMIT`), which therefore would keep them all: the same hat matrix, 3× cheaper.
CHOLESKY_RCOND = 1e-3


def hat_factor(J: FloatArray) -> FloatArray:
    """``F (M, k)`` with ``F Fᵀ`` the hat matrix ``J (JᵀJ)⁺ Jᵀ``: ``(L⁻¹ Jᵀ)ᵀ`` from the Cholesky
    factor ``L`` of ``JᵀJ`` when ``J`` is well conditioned (:data:`CHOLESKY_RCOND`), else the left
    singular vectors of ``J`` above :data:`RCOND_LIMIT`."""
    norms = np.linalg.norm(J, axis=0)
    live = norms > 0  # the hat matrix does not depend on the columns' scales: equilibrate them
    A = J[:, live] / norms[live]
    H = A.T @ A
    eigenvalues = np.linalg.eigvalsh(H)
    if eigenvalues.size and eigenvalues[0] > CHOLESKY_RCOND**2 * eigenvalues[-1]:
        L = np.linalg.cholesky(H)
        return np.linalg.solve(L, A.T).T
    U, s, _ = np.linalg.svd(A, full_matrices=False)
    rank = s > s[0] * RCOND_LIMIT if s.size and s[0] > 0 else np.zeros(s.size, dtype=bool)
    return U[:, rank]


def leverages(J: FloatArray) -> FloatArray:
    """Diagonal of the hat matrix ``J (JᵀJ)⁺ Jᵀ`` (rows' leverages, ``h_i = |F_i|²``, :func:`hat_factor`)."""
    return np.sum(hat_factor(J) ** 2, axis=1)


#: The image's axes, in the order of a sample's residual expressed in the image frame.
IMAGE_AXES = ("lateral", "depth", "normal")


def image_axis_levels(
    normalised: FloatArray, J: FloatArray, image_rows: slice, sigma_image: float, R_R_I: FloatArray
) -> dict[str, NoiseLevel]:
    """The image samples' noise level along each image axis (:data:`IMAGE_AXES`), metres.

    The image group's level (:func:`noise_levels`) is per coordinate of ``base_link``: it pools the
    annotation noise, which lies in the image plane (lateral and depth), with the needle tip's
    distance from the plane and the robot's error, and so states √(2/3) of the annotation noise when
    the rest is small. Here each sample's residual ``r_i`` (rows ``image_rows`` of ``normalised`` times
    ``sigma_image``, 3 per sample in ``base_link``) is projected on the image's axis ``a_i`` at its
    pose (``R_R_I (n, 3, 3)``, columns lateral, depth, normal) and
    ``σ_a² = Σ_i (a_iᵀ r_i)² / (n − Σ_i a_iᵀ H_ii a_i)``, ``H_ii`` the sample's 3 × 3 block of the
    weighted problem's hat matrix (the unbiased estimate for a linear model, as for the groups).
    """
    F = hat_factor(J)[image_rows].reshape(len(R_R_I), 3, -1)  # (n, 3, k)
    raw = (normalised[image_rows] * sigma_image).reshape(-1, 3)
    along = np.einsum("nja,nj->na", R_R_I, raw)  # (n, 3): residuals along each image axis
    lever = np.einsum("nja,njk->nak", R_R_I, F)  # (n, 3, k): a_iᵀ F_i
    h = np.sum(lever**2, axis=2)  # (n, 3): a_iᵀ H_ii a_i
    out = {}
    for k, axis in enumerate(IMAGE_AXES):
        dof = float(len(raw) - h[:, k].sum())
        if dof < MIN_NOISE_DOF:
            continue
        scale = max(float(np.sqrt(np.sum(along[:, k] ** 2) / dof)), RESOLUTION_M)
        out[axis] = NoiseLevel(scale, dof, "residuals", f"{scale * 1e3:.3f} mm along the image's {axis} axis")
    return out


def noise_levels(
    normalised: FloatArray,
    J: FloatArray,
    rows: dict[str, slice],
    sigma: dict[str, float],
    robust: bool,
) -> dict[str, NoiseLevel]:
    """Each group's noise level from its residuals, with the degrees-of-freedom correction.

    ``normalised`` and ``J`` are the residuals and Jacobian of the weighted problem (rows divided
    by ``sigma``). Final stage: ``σ_g² = Σ_g r_raw² / (n_g − Σ_g h_ii)``; robust stage: the same
    correction applied to 1.4826 × the median absolute residual. Groups with fewer than
    :data:`MIN_NOISE_DOF` residual degrees of freedom take an assumed level (see the module).
    """
    h = leverages(J)
    out: dict[str, NoiseLevel] = {}
    for g in GROUPS:
        raw = normalised[rows[g]] * sigma[g]
        dof = float(raw.size - h[rows[g]].sum())
        if dof < MIN_NOISE_DOF:
            continue
        if robust:
            scale = 1.4826 * float(np.median(np.abs(raw))) * np.sqrt(raw.size / dof)
        else:
            scale = float(np.sqrt(np.sum(raw**2) / dof))
        out[g] = measured_level(scale, dof)
    for g in GROUPS:
        if g in out:
            continue
        dof = float(normalised[rows[g]].size - h[rows[g]].sum())
        out[g] = assumed_level(g, out, dof)
    return out


def measured_level(scale: float, dof: float) -> NoiseLevel:
    """A group's level estimated from its residuals, ``scale`` (metres) on ``dof`` residual degrees
    of freedom (at least :data:`MIN_NOISE_DOF`): at :data:`RESOLUTION_M` when at or below it."""
    if scale <= RESOLUTION_M:
        return NoiseLevel(RESOLUTION_M, dof, "below resolution", f"below {RESOLUTION_M * 1e3:.3f} mm (resolution)")
    return NoiseLevel(scale, dof, "residuals", f"{scale * 1e3:.3f} mm ({dof:.0f} residual dof)")


#: The group whose level a group with too few residual degrees of freedom takes, if that one has
#: its own: the axes moves are measured as the touches are (the same arms, the same tips).
POOLED_WITH = {"axes": "touch"}


def assumed_level(group: str, measured: dict[str, NoiseLevel], dof: float) -> NoiseLevel:
    """The level of ``group``, which has too few residual degrees of freedom (``dof``) for its own:
    that of the group it is pooled with (:data:`POOLED_WITH`) when ``measured`` (the groups with
    their own) has it, else :data:`INITIAL_SIGMA`'s."""
    partner = POOLED_WITH.get(group)
    if partner is not None and partner in measured:
        level, why = measured[partner].sd_m, "the touches' level"
    else:
        level, why = INITIAL_SIGMA[group], "the prior level"
    return NoiseLevel(level, dof, "assumed", f"{level * 1e3:.3f} mm assumed ({why}: {dof:.0f} residual dof)")


def noise_share(
    normalised: FloatArray,
    J: FloatArray,
    J_c: FloatArray,
    robot_covariance: FloatArray,
    rows: dict[str, slice],
    noise: dict[str, NoiseLevel],
) -> dict[str, float]:
    """Each group's residual variance that the session's noise explains, as a fraction of its level.

    The residuals of the weighted problem are ``(I − H)(n + J_c c)``: the robot's error adds
    ``Σ_i [(I − H) J_c Σ_c J_cᵀ (I − H)]_ii`` (expected) to a group's residual sum of squares, on top
    of the noise's ``σ² (n_g − Σ h_ii)``. The noise levels estimated from the residuals (the fit's
    weights) contain both; the share ``(RSS_g − robot_g) / RSS_g`` (floored at 0: a stated accuracy
    that explains all the scatter leaves no noise) is what the noise part of the covariance keeps,
    so the robot's error is not counted twice. Groups with an assumed level keep it whole.
    """
    norms = np.linalg.norm(J, axis=0)
    live = norms > 0
    U, s, _ = np.linalg.svd(J[:, live] / norms[live], full_matrices=False)
    U = U[:, s > s[0] * RCOND_LIMIT]
    M = J_c - U @ (U.T @ J_c)  # (I − H) J_c
    robot_rows = np.einsum("ij,jk,ik->i", M, robot_covariance, M)
    out = {}
    for g, part in rows.items():
        rss = float(np.sum(normalised[part] ** 2))
        keep = noise[g].source == "residuals" and rss > 0
        out[g] = max(0.0, 1.0 - float(robot_rows[part].sum()) / rss) if keep else 1.0
    return out


def robot_posterior(
    normalised: FloatArray, J: FloatArray, J_c: FloatArray, robot_covariance: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """The joints' origin errors ``c`` given the fit's residuals: mean ``(6 nq,)`` and covariance
    ``(6 nq, 6 nq)`` (metres, radians).

    The stated accuracy is ``c``'s prior ``N(0, Σ_c)``. The weighted residuals are
    ``(I − H)(n + J_c c)``: in the residuals' own space (orthonormal basis ``Q`` of the complement of
    ``J``'s columns) ``Qᵀr = M c + Qᵀn`` with ``M = Qᵀ J_c``, the noise's covariance ``I`` in the
    fit's weights (each group's level whole: it holds some of the robot's scatter too, so the
    posterior leans to the prior; with :func:`noise_share` taken out, a group the stated accuracy
    explains in full would be noise-free and its noise read as the robot's error). Then
    ``K = Σ_c Mᵀ (M Σ_c Mᵀ + I)⁻¹``, mean ``K Qᵀr``, covariance ``Σ_c − K M Σ_c``: what the residuals
    show of the robot's error in this session (less than stated, or more) enters the predicted
    landing error through them.
    """
    norms = np.linalg.norm(J, axis=0)
    live = norms > 0
    U, s, _ = np.linalg.svd(J[:, live] / norms[live], full_matrices=True)
    rank = int(np.sum(s > s[0] * RCOND_LIMIT)) if s.size and s[0] > 0 else 0
    Q = U[:, rank:]
    M = Q.T @ J_c
    K = np.linalg.solve(M @ robot_covariance @ M.T + np.eye(len(M)), M @ robot_covariance).T
    posterior = robot_covariance - K @ M @ robot_covariance
    return K @ (Q.T @ normalised), 0.5 * (posterior + posterior.T)
