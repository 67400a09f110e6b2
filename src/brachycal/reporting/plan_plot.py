"""Figure of a plan: the sample grid in base_link with the visiting path, and image coverage."""

from __future__ import annotations

import io
import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.figure import Figure

from brachycal.reporting.figures import save_figure
from brachycal.se3 import FloatArray

if TYPE_CHECKING:  # a type only: drawing a plan needs no planner (mink)
    from brachycal.planning.plan import Plan

#: The plan figure's resolution (dots per inch of its 11 x 4.8 inch canvas).
PLAN_DPI = 110


def plan_figure(plan: Plan) -> Figure:
    """Two panels: the needle-tip targets in ``base_link`` (mm) with the visiting path, and the
    expected needle-tip pixels over the field of view (infeasible points marked in red)."""
    spec = plan.spec
    return _figure(
        np.array([pose.point.p_base for pose in plan.poses]).reshape(-1, 3),
        np.array([item.point.p_base for item in plan.infeasible]).reshape(-1, 3),
        np.array([pose.check.uv_px for pose in plan.poses]).reshape(-1, 2),
        np.array([item.point.uv_px for item in plan.infeasible]).reshape(-1, 2),
        spec.fov.outline_px(spec.spacing_m),
    )


def _figure(
    p_planned_m: FloatArray,
    p_infeasible_m: FloatArray,
    uv_planned: FloatArray,
    uv_infeasible: FloatArray,
    outline: FloatArray,
) -> Figure:
    """:func:`plan_figure` from arrays: targets ``(N, 3)`` and ``(K, 3)`` (metres, ``base_link``; planned
    in visiting order, infeasible), their pixels ``(N, 2)`` and ``(K, 2)``, the field of view's outline
    ``(M, 2)`` (pixels)."""
    fig = Figure(figsize=(11, 4.8))
    # Fixed margins, not layout="tight": the tight layout engine measures the text of both panels
    # and takes ~0.2 s of the plan command's ~1.9 s; these fit the two panels' labels.
    fig.subplots_adjust(left=0.02, right=0.98, bottom=0.1, top=0.92, wspace=0.1)
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    if len(p_planned_m):
        p = p_planned_m * 1e3
        ax.plot(p[:, 0], p[:, 1], p[:, 2], color="0.6", lw=0.8, label="visiting order")
        ax.scatter(p[:, 0], p[:, 1], p[:, 2], c=np.arange(len(p)), cmap="viridis", s=18, label="planned")
    if len(p_infeasible_m):
        bad = p_infeasible_m * 1e3
        ax.scatter(bad[:, 0], bad[:, 1], bad[:, 2], marker="x", color="red", s=30, label="infeasible")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_zlabel("z (mm)")
    ax.set_title(f"{len(p_planned_m)} needle-tip targets in the robot's base frame")
    ax.legend(loc="upper left", fontsize=8)

    ax2 = fig.add_subplot(1, 2, 2)
    ax2.plot(outline[:, 0], outline[:, 1], color="0.3", lw=1, label="field of view")
    if len(uv_planned):
        ax2.scatter(uv_planned[:, 0], uv_planned[:, 1], s=14, c="tab:blue", label="expected needle tip")
    if len(uv_infeasible):
        ax2.scatter(uv_infeasible[:, 0], uv_infeasible[:, 1], marker="x", color="red", s=30, label="infeasible")
    ax2.set_xlabel("u (px)")
    ax2.set_ylabel("v (px)")
    ax2.invert_yaxis()
    ax2.set_aspect("equal")
    ax2.set_title("image coverage")
    ax2.legend(loc="lower right", fontsize=8)
    return fig


def plot_plan(plan: Plan, path: str | os.PathLike[str]) -> Path:
    """Save :func:`plan_figure` as ``path`` (a PNG for ``.png``)."""
    save_figure(plan_figure(plan), path, dpi=PLAN_DPI)
    return Path(path)


def warm_up_plan_figure() -> None:
    """Draw a stand-in plan figure (every kind of artist :func:`plan_figure` uses) into memory and
    discard it.

    Matplotlib's first drawing of a process loads the fonts and fills its text, path and colormap
    caches (~0.25 s of the ~0.45 s a first plan figure takes); the ``plan`` command's drawing process
    does it while the planner runs, so that the figure of the plan is drawn warm. The caches only
    memoise: the plan's figure is the same, pixel for pixel (``tests/test_planning.py``).
    """
    rng = np.random.default_rng(0)
    p = 0.8 + 0.02 * rng.standard_normal((8, 3))
    uv = 300.0 + 50.0 * rng.standard_normal((8, 2))
    outline = np.array([[0.0, 0.0], [600.0, 0.0], [600.0, 400.0], [0.0, 400.0], [0.0, 0.0]])
    _figure(p, p[:2], uv, uv[:2], outline).savefig(io.BytesIO(), dpi=PLAN_DPI, format="png")
