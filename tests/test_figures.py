"""Figures: every builder returns a matplotlib ``Figure`` and leaves the caller's matplotlib alone.

Library code must not change global state: a ``matplotlib.use("Agg")`` inside a figure function
switched a notebook's backend, and every plot after it showed nothing.
"""

from __future__ import annotations

import ast
from pathlib import Path

import matplotlib
import numpy as np
import pytest
from matplotlib.figure import Figure

TESTS = Path(__file__).parent


def every_figure(folder: Path) -> list[Figure]:
    """Build every figure of the library and save each through its save function into ``folder``."""
    from brachycal import reporting
    from brachycal.calibration.metrics import ErrorStats
    from brachycal.model import Robot
    from brachycal.planning import PlanSpec, plan_poses
    from brachycal.reporting import figures, scene

    rng = np.random.default_rng(0)
    p_real = rng.normal(scale=0.02, size=(12, 3))
    stats = {m: ErrorStats.between(p_real, p_real + rng.normal(scale=1e-3, size=(12, 3))) for m in ("kabsch", "lsq")}
    ids = [f"s{k}" for k in range(12)]
    summary = [
        {
            "method": method,
            "annotation_px": 1.0,
            "edge_mm": 40.0,
            "sound_speed": True,
            "outlier_rate": 0.0,
            "robot_error": "well-built",
            "samples": n,
            "loo_mae_mm_mean": 0.5,
            "loo_mae_mm_sd": 0.1,
            "target_mae_mm_mean": 1.0,
            "target_mae_mm_sd": 0.2,
        }
        for method in ("kabsch", "chain")
        for n in (27, 64)
    ]
    robot = Robot.load()
    plan = plan_poses(robot, PlanSpec(points_per_axis=2))
    the_scene = scene.robot_scene(robot, robot.neutral())
    built = [
        figures.error_histogram_figure(stats["kabsch"], "t"),
        figures.points_3d_figure(p_real, p_real + 1e-3, "t"),
        figures.method_comparison_figure(stats, "t"),
        figures.residuals_per_sample_figure(stats, ids),
        figures.study_figure(summary),
        reporting.plan_figure(plan),
        scene.scene_figure(the_scene),
    ]
    figures.error_histogram(stats["kabsch"], folder / "hist.png", "t")
    figures.points_3d(p_real, p_real + 1e-3, folder / "points.png", "t")
    figures.method_comparison(stats, folder / "methods.png", "t")
    figures.residuals_per_sample(stats, ids, folder / "residuals.png")
    figures.save_figure(built[4], folder / "study.png", dpi=50)
    reporting.plot_plan(plan, folder / "plan.png")
    scene.render_png(the_scene, folder / "scene.png")
    return built


@pytest.fixture
def callers_matplotlib():
    """The caller's own matplotlib state: a backend other than Agg and a setting of their own."""
    import matplotlib.pyplot as plt

    backend = matplotlib.get_backend()
    matplotlib.use("svg")
    try:
        with matplotlib.rc_context({"lines.linewidth": 3.5}):
            yield plt
    finally:
        matplotlib.use(backend)


def test_figures_leave_the_callers_backend_settings_and_pyplot_alone(tmp_path, callers_matplotlib):
    plt = callers_matplotlib
    rc_before, open_before = dict(matplotlib.rcParams), plt.get_fignums()
    built = every_figure(tmp_path)
    assert all(isinstance(fig, Figure) for fig in built)
    assert [len(fig.axes) for fig in built] == [1, 1, 1, 1, 2, 2, 1]
    assert matplotlib.get_backend() == "svg"
    assert dict(matplotlib.rcParams) == rc_before
    assert plt.get_fignums() == open_before  # nothing registered with pyplot, nothing left open
    saved = sorted(p.name for p in tmp_path.iterdir())
    assert saved == sorted(f"{n}.png" for n in ("hist", "points", "methods", "residuals", "study", "plan", "scene"))
    assert all((tmp_path / name).read_bytes().startswith(b"\x89PNG") for name in saved)


def _pyplot_uses(path: Path) -> list[str]:
    """``file:line`` of every pyplot import and ``matplotlib.use`` call in a Python file."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        names = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            names = [f"{node.module}.{alias.name}" for alias in node.names]
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "use":
            names = [ast.unparse(node.func)]
        if any(n.startswith("matplotlib.pyplot") or n in ("matplotlib.use", "mpl.use") for n in names):
            found.append(f"{path.name}:{node.lineno}")
    return found


def test_library_code_neither_imports_pyplot_nor_picks_a_backend():
    # matplotlib itself may import pyplot to resolve the backend the caller configured (boxplot
    # reads every rcParam); what is checked here is that brachycal never does either on its own.
    sources = sorted((TESTS.parent / "src" / "brachycal").rglob("*.py"))
    assert len(sources) > 50  # the package was found
    assert [hit for path in sources for hit in _pyplot_uses(path)] == []
