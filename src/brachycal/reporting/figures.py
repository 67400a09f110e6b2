"""Figures of a calibration, after the paper's Figs. 10 and 11, plus the targeting error, the
predicted landing error over the image, and a study.

Every figure has a builder that returns a :class:`matplotlib.figure.Figure` (shown by Jupyter when
it is a cell's last value, or with ``display(fig)``) and a function that saves it. Neither touches
pyplot or the backend: a bare ``Figure`` renders through the Agg canvas matplotlib picks for the
file's format, so the caller's backend, open figures and ``rcParams`` stay as they were.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import ArrayLike
from scipy.interpolate import RegularGridInterpolator

from brachycal.calibration.labels import ALL_LABELS, METHOD_LABELS
from brachycal.calibration.metrics import ErrorStats
from brachycal.data.session import ImageSector
from brachycal.io import atomic_path
from brachycal.planning.spec import SectorFOV


def save_figure(fig: Figure, path: str | os.PathLike[str], *, dpi: int) -> None:
    """Save ``fig`` as ``path`` (format from its suffix) atomically.

    An existing file is replaced, as matplotlib does; a command claims its figures up front
    (and refuses existing ones without ``--force``) and passes the staging path. A bare
    ``Figure`` (what the builders here return) needs no closing; a pyplot figure stays open, as
    pyplot's state is its owner's.
    """
    with atomic_path(path, force=True) as staged:
        fig.savefig(staged, dpi=dpi)


def error_histogram_figure(stats: ErrorStats, title: str) -> Figure:
    """Fig. 11: histogram of per-sample error magnitudes (mm) with MAE and RMSE marked."""
    fig = Figure(figsize=(6, 3.8), layout="tight")
    ax = fig.add_subplot()
    errors = stats.errors_m * 1e3
    bins = np.linspace(0, max(errors.max() * 1.05, 1e-6), 17).tolist()  # matplotlib's stubs take a sequence
    ax.hist(errors, bins=bins, color="tab:blue", edgecolor="white")
    ax.axvline(stats.mae_mm, color="k", ls="--", lw=1, label=f"MAE {stats.mae_mm:.2f} mm")
    ax.axvline(stats.rmse_mm, color="tab:red", ls=":", lw=1, label=f"RMSE {stats.rmse_mm:.2f} mm")
    ax.set_xlabel("error (mm)")
    ax.set_ylabel("samples")
    ax.set_title(title)
    ax.legend()
    return fig


def error_histogram(stats: ErrorStats, path: str | os.PathLike[str], title: str) -> Path:
    """Save :func:`error_histogram_figure` as ``path`` (PNG at 110 dpi for a ``.png``)."""
    save_figure(error_histogram_figure(stats, title), path, dpi=110)
    return Path(path)


def points_3d_figure(p_real_m: ArrayLike, p_cal_m: ArrayLike, title: str) -> Figure:
    """Fig. 10 (e): real needle tips ``(N, 3)`` and their calibrated estimates ``(N, 3)``, metres in
    the robot's base frame (``base_link`` on the SDA10F), drawn in millimetres."""
    real, cal = np.asarray(p_real_m) * 1e3, np.asarray(p_cal_m) * 1e3
    fig = Figure(figsize=(6, 5), layout="tight")
    ax = fig.add_subplot(projection="3d")
    ax.scatter(*real.T, s=16, color="tab:blue", label="real (robot, needle arm)")
    ax.scatter(*cal.T, s=16, marker="^", color="tab:orange", label="calibrated (image, probe arm)")
    for a, b in zip(real, cal, strict=True):
        ax.plot(*np.stack([a, b]).T, color="0.5", lw=0.6)
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_zlabel("z (mm)")
    ax.set_title(title)
    ax.legend(fontsize=8)
    return fig


def points_3d(p_real_m: ArrayLike, p_cal_m: ArrayLike, path: str | os.PathLike[str], title: str) -> Path:
    """Save :func:`points_3d_figure` as ``path``."""
    save_figure(points_3d_figure(p_real_m, p_cal_m, title), path, dpi=110)
    return Path(path)


def method_comparison_figure(stats: Mapping[str, ErrorStats], title: str) -> Figure:
    """Box plot of per-target errors (mm) for each method."""
    fig = Figure(figsize=(7, 3.8), layout="tight")
    ax = fig.add_subplot()
    ax.boxplot([s.errors_m * 1e3 for s in stats.values()], showmeans=True)
    ax.set_xticks(range(1, len(stats) + 1), [METHOD_LABELS.get(m, m) for m in stats], rotation=15)
    ax.set_ylabel("error (mm)")
    ax.set_title(title)
    return fig


def method_comparison(stats: Mapping[str, ErrorStats], path: str | os.PathLike[str], title: str) -> Path:
    """Save :func:`method_comparison_figure` as ``path``."""
    save_figure(method_comparison_figure(stats, title), path, dpi=110)
    return Path(path)


def residuals_per_sample_figure(stats: Mapping[str, ErrorStats], sample_ids: Sequence[str]) -> Figure:
    """Leave-one-out error of every sample (mm), one line per method."""
    fig = Figure(figsize=(9, 3.6), layout="tight")
    ax = fig.add_subplot()
    x = np.arange(len(sample_ids))
    for method, s in stats.items():
        ax.plot(x, s.errors_m * 1e3, marker=".", lw=0.8, label=METHOD_LABELS.get(method, method))
    step = max(1, len(sample_ids) // 16)
    ax.set_xticks(x[::step], [sample_ids[i] for i in x[::step]], rotation=45, fontsize=7)
    ax.set_ylabel("LOO error (mm)")
    ax.set_title("Residual per sample (leave-one-out)")
    ax.legend(fontsize=7)
    return fig


def residuals_per_sample(stats: Mapping[str, ErrorStats], sample_ids: list[str], path: str | os.PathLike[str]) -> Path:
    """Save :func:`residuals_per_sample_figure` as ``path``."""
    save_figure(residuals_per_sample_figure(stats, sample_ids), path, dpi=110)
    return Path(path)


def landing_map_raster(
    pixels_px: ArrayLike,
    rms_mm: ArrayLike,
    size_px: ArrayLike,
    spacing_m: ArrayLike,
    sector: ImageSector | None,
) -> np.ma.MaskedArray:
    """The predicted landing error map on every pixel: ``(H, W)`` mm, indexed ``[v, u]``.

    ``pixels_px`` ``(G, 2)`` is a regular grid of pixels ``(u, v)`` and ``rms_mm`` ``(G,)`` the
    predicted RMS landing error at each (``ChainResult.fov_px`` and ``predicted_fov_mm``). Between
    grid nodes the value is bilinear; beyond the outermost nodes (the image's last part-cell) it is
    the nearest node's. Pixels outside the probe's imaging ``sector`` are masked (they show no
    tissue: no needle tip is ever seen there); with no sector stated, none is.
    """
    uv, values = np.asarray(pixels_px, float), np.asarray(rms_mm, float)
    us, vs = np.unique(uv[:, 0]), np.unique(uv[:, 1])
    if len(us) * len(vs) != len(uv) or len(us) < 2 or len(vs) < 2:
        raise ValueError(f"the map's {len(uv)} pixels are not a regular grid of at least 2 x 2")
    grid = np.full((len(vs), len(us)), np.nan)
    grid[np.searchsorted(vs, uv[:, 1]), np.searchsorted(us, uv[:, 0])] = values
    width, height = (int(n) for n in np.asarray(size_px))
    v, u = np.mgrid[0:height, 0:width]
    at = np.column_stack([np.clip(v.ravel(), vs[0], vs[-1]), np.clip(u.ravel(), us[0], us[-1])])
    raster = RegularGridInterpolator((vs, us), grid)(at).reshape(height, width)
    outside = np.zeros((height, width), dtype=bool)
    if sector is not None:
        margin = sector.margin_to_edge(np.column_stack([u.ravel(), v.ravel()]), spacing_m)
        outside = (margin < 0).reshape(height, width)
    return np.ma.masked_array(raster, mask=outside)


def landing_map_figure(
    pixels_px: ArrayLike,
    rms_mm: ArrayLike,
    size_px: ArrayLike,
    spacing_m: ArrayLike,
    sector: ImageSector | None,
    method: str,
) -> Figure:
    """The predicted RMS landing error (mm) over the image of calibration ``method`` (a key of
    :data:`~brachycal.calibration.labels.ALL_LABELS`), probe at the central sample pose.

    Drawn in the image's own orientation (u to the right, v downward with depth) over the probe's
    imaging ``sector`` only, its outline drawn; outside it the figure is blank
    (:func:`landing_map_raster`). With no sector stated the whole image is coloured and the title
    says so. Arguments as :func:`landing_map_raster`.
    """
    raster = landing_map_raster(pixels_px, rms_mm, size_px, spacing_m, sector)
    height, width = raster.shape
    fig = Figure(figsize=(7, 4.2), layout="constrained")
    ax = fig.add_subplot()
    image = ax.imshow(
        raster, origin="upper", extent=(-0.5, width - 0.5, height - 0.5, -0.5), cmap="viridis", interpolation="nearest"
    )
    if sector is not None:
        outline = SectorFOV.of(sector).outline_px(spacing_m)
        ax.plot(*outline.T, color="0.3", lw=0.8)
    ax.set_xlim(-0.5, width - 0.5)
    ax.set_ylim(height - 0.5, -0.5)  # v grows downward, with depth, as on the scanner's screen
    ax.set_aspect("equal")
    ax.set_xlabel("u (px)")
    ax.set_ylabel("v (px, depth: downward)")
    fig.colorbar(image, ax=ax, label="predicted landing error, RMS (mm)")
    where = "over the probe's imaging sector" if sector is not None else "whole image: the session states no sector"
    ax.set_title(
        f"Predicted landing error, {ALL_LABELS.get(method, method)} calibration\n"
        f"probe at the central sample pose; {where}",
        fontsize=9,
    )
    return fig


def landing_map(
    pixels_px: ArrayLike,
    rms_mm: ArrayLike,
    size_px: ArrayLike,
    spacing_m: ArrayLike,
    sector: ImageSector | None,
    method: str,
    path: str | os.PathLike[str],
) -> Path:
    """Save :func:`landing_map_figure` as ``path``."""
    save_figure(landing_map_figure(pixels_px, rms_mm, size_px, spacing_m, sector, method), path, dpi=110)
    return Path(path)


def study_figure(summary: Sequence[Mapping[str, Any]]) -> Figure:
    """``brachycal study``: leave-one-out MAE and end-to-end targeting MAE (mm, mean ± SD over seeds)
    against the number of samples, one line per method and setting.

    Args:
        summary: rows of :func:`brachycal.studies.study.summarise`.
    """
    fig = Figure(figsize=(11, 4), layout="tight")
    axes = fig.subplots(1, 2, sharey=True)

    def setting(s: Mapping[str, Any]) -> tuple:
        return s["method"], s["annotation_px"], s["edge_mm"], s["sound_speed"], s["outlier_rate"], s["robot_error"]

    for key in sorted({setting(s) for s in summary}):
        method, ann, edge, sound, _, level = key
        rows = sorted((s for s in summary if setting(s) == key), key=lambda s: s["samples"])
        n = np.array([s["samples"] for s in rows])
        label = f"{ALL_LABELS[method]}, {ann:g} px, {edge:g} mm" + ("" if sound else ", tissue")
        label += "" if level == "well-built" else f", {level} robot"
        for ax, figure in zip(axes, ("loo_mae_mm", "target_mae_mm"), strict=True):
            ax.errorbar(
                n,
                [s[f"{figure}_mean"] for s in rows],
                yerr=[s[f"{figure}_sd"] for s in rows],
                marker="o",
                capsize=3,
                label=label,
            )
    axes[0].set_title("leave-one-out MAE (what a lab sees)")
    axes[1].set_title("end-to-end targeting MAE (truth)")
    for ax in axes:
        ax.set_xlabel("samples")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("mm")
    axes[1].legend(fontsize=7)
    return fig
