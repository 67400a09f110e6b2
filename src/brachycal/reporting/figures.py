"""Figures of a calibration, after the paper's Figs. 10 and 11, plus the targeting error."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from brachycal.calibration.image_to_probe import METHOD_LABELS
from brachycal.calibration.metrics import ErrorStats


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def error_histogram(stats: ErrorStats, path: str | os.PathLike[str], title: str) -> Path:
    """Fig. 11: histogram of per-sample error magnitudes (mm) with MAE and RMSE marked."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 3.8))
    errors = stats.errors_m * 1e3
    ax.hist(errors, bins=np.linspace(0, max(errors.max() * 1.05, 1e-6), 17), color="tab:blue", edgecolor="white")
    ax.axvline(stats.mae_mm, color="k", ls="--", lw=1, label=f"MAE {stats.mae_mm:.2f} mm")
    ax.axvline(stats.rmse_mm, color="tab:red", ls=":", lw=1, label=f"RMSE {stats.rmse_mm:.2f} mm")
    ax.set_xlabel("error (mm)")
    ax.set_ylabel("samples")
    ax.set_title(title)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def points_3d(p_real_m: ArrayLike, p_cal_m: ArrayLike, path: str | os.PathLike[str], title: str) -> Path:
    """Fig. 10 (e): real needle tips and their calibrated estimates in ``base_link`` (mm)."""
    plt = _pyplot()
    real, cal = np.asarray(p_real_m) * 1e3, np.asarray(p_cal_m) * 1e3
    fig = plt.figure(figsize=(6, 5))
    ax = fig.add_subplot(projection="3d")
    ax.scatter(*real.T, s=16, color="tab:blue", label="real (robot, right arm)")
    ax.scatter(*cal.T, s=16, marker="^", color="tab:orange", label="calibrated (image, left arm)")
    for a, b in zip(real, cal, strict=True):
        ax.plot(*np.stack([a, b]).T, color="0.5", lw=0.6)
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_zlabel("z (mm)")
    ax.set_title(title)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def method_comparison(stats: Mapping[str, ErrorStats], path: str | os.PathLike[str], title: str) -> Path:
    """Box plot of per-target errors (mm) for each method."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 3.8))
    ax.boxplot([s.errors_m * 1e3 for s in stats.values()], showmeans=True)
    ax.set_xticks(range(1, len(stats) + 1), [METHOD_LABELS.get(m, m) for m in stats], rotation=15)
    ax.set_ylabel("error (mm)")
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def residuals_per_sample(stats: Mapping[str, ErrorStats], sample_ids: list[str], path: str | os.PathLike[str]) -> Path:
    """Leave-one-out error of every sample (mm), one line per method."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(9, 3.6))
    x = np.arange(len(sample_ids))
    for method, s in stats.items():
        ax.plot(x, s.errors_m * 1e3, marker=".", lw=0.8, label=METHOD_LABELS.get(method, method))
    step = max(1, len(sample_ids) // 16)
    ax.set_xticks(x[::step], [sample_ids[i] for i in x[::step]], rotation=45, fontsize=7)
    ax.set_ylabel("LOO error (mm)")
    ax.set_title("Residual per sample (leave-one-out)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)
