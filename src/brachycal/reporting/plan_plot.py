"""Figure of a plan: the sample grid in base_link with the visiting path, and image coverage."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.figure import Figure

from brachycal.reporting.figures import save_figure

if TYPE_CHECKING:  # a type only: drawing a plan needs no planner (mink)
    from brachycal.planning.plan import Plan


def plan_figure(plan: Plan) -> Figure:
    """Two panels: the needle-tip targets in ``base_link`` (mm) with the visiting path, and the
    expected needle-tip pixels over the field of view (infeasible points marked in red)."""
    fig = Figure(figsize=(11, 4.8))
    # Fixed margins, not layout="tight": the tight layout engine measured the text of both panels
    # and took ~0.2 s of the plan command's ~1.9 s (issue 13); these fit the two panels' labels.
    fig.subplots_adjust(left=0.02, right=0.98, bottom=0.1, top=0.92, wspace=0.1)
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    if plan.poses:
        p = np.array([pose.point.p_base for pose in plan.poses]) * 1e3
        ax.plot(p[:, 0], p[:, 1], p[:, 2], color="0.6", lw=0.8, label="visiting order")
        ax.scatter(p[:, 0], p[:, 1], p[:, 2], c=np.arange(len(p)), cmap="viridis", s=18, label="planned")
    if plan.infeasible:
        bad = np.array([item.point.p_base for item in plan.infeasible]) * 1e3
        ax.scatter(bad[:, 0], bad[:, 1], bad[:, 2], marker="x", color="red", s=30, label="infeasible")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_zlabel("z (mm)")
    ax.set_title(f"{len(plan.poses)} needle-tip targets in the robot's base frame")
    ax.legend(loc="upper left", fontsize=8)

    ax2 = fig.add_subplot(1, 2, 2)
    spec = plan.spec
    outline = spec.fov.outline_px(spec.spacing_m)
    ax2.plot(outline[:, 0], outline[:, 1], color="0.3", lw=1, label="field of view")
    if plan.poses:
        uv = np.array([pose.check.uv_px for pose in plan.poses])
        ax2.scatter(uv[:, 0], uv[:, 1], s=14, c="tab:blue", label="expected needle tip")
    if plan.infeasible:
        uv_bad = np.array([item.point.uv_px for item in plan.infeasible])
        ax2.scatter(uv_bad[:, 0], uv_bad[:, 1], marker="x", color="red", s=30, label="infeasible")
    ax2.set_xlabel("u (px)")
    ax2.set_ylabel("v (px)")
    ax2.invert_yaxis()
    ax2.set_aspect("equal")
    ax2.set_title("image coverage")
    ax2.legend(loc="lower right", fontsize=8)
    return fig


def plot_plan(plan: Plan, path: str | os.PathLike[str]) -> Path:
    """Save :func:`plan_figure` as ``path`` (a PNG for ``.png``)."""
    save_figure(plan_figure(plan), path, dpi=110)
    return Path(path)
