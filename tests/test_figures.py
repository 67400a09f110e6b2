"""Figures: every builder returns a matplotlib ``Figure`` and leaves the caller's matplotlib alone;
the predicted landing error map says what it shows and colours only the probe's imaging sector.

Library code must not change global state: a ``matplotlib.use("Agg")`` inside a figure function
switched a notebook's backend, and every plot after it showed nothing.

The landing error map (``calibrate --solve chain --report``):

- its axes are the image's pixels, u to the right and v downward (depth), labelled in px; its
  colour bar is labelled in mm; its title names the calibration it shows;
- it is blank (masked, transparent) outside the sector the session states (``[image.sector]``):
  no needle tip is ever seen there; inside, every pixel carries the predicted value (bilinear
  between the map's grid nodes, so a map linear in u and v is reproduced exactly);
- with no sector stated, the whole image is coloured and the title says why.
"""

from __future__ import annotations

import ast
from pathlib import Path

import matplotlib
import numpy as np
import pytest
from matplotlib.figure import Figure

TESTS = Path(__file__).parent
#: The paper's image and a convex probe's sector: apex at the top centre, 70 mm deep, 120° open.
SIZE_PX, SPACING_M, STEP_PX = (1080, 720), (0.19e-3, 0.19e-3), 60.0


def sector():
    from brachycal.data.session import ImageSector

    return ImageSector((540.0, 0.0), 0.070, float(np.radians(120.0)))


def linear_map() -> tuple[np.ndarray, np.ndarray]:
    """A map on the chain report's grid (every 60 px from the image's corner): 0.1 mm + 0.1 mm per
    1000 px along u + 0.2 mm per 1000 px along v, which bilinear interpolation reproduces exactly."""
    grid = np.array([(u, v) for v in np.arange(0, SIZE_PX[1], STEP_PX) for u in np.arange(0, SIZE_PX[0], STEP_PX)])
    return grid, rms_at(grid)


def rms_at(uv: np.ndarray) -> np.ndarray:
    uv = np.atleast_2d(uv)
    return 0.1 + 1e-4 * uv[:, 0] + 2e-4 * uv[:, 1]


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
    grid, rms = linear_map()
    built = [
        figures.error_histogram_figure(stats["kabsch"], "t"),
        figures.points_3d_figure(p_real, p_real + 1e-3, "t"),
        figures.method_comparison_figure(stats, "t"),
        figures.residuals_per_sample_figure(stats, ids),
        figures.study_figure(summary),
        reporting.plan_figure(plan),
        scene.scene_figure(the_scene),
        figures.landing_map_figure(grid, rms, SIZE_PX, SPACING_M, sector(), "chain"),
    ]
    figures.error_histogram(stats["kabsch"], folder / "hist.png", "t")
    figures.points_3d(p_real, p_real + 1e-3, folder / "points.png", "t")
    figures.method_comparison(stats, folder / "methods.png", "t")
    figures.residuals_per_sample(stats, ids, folder / "residuals.png")
    figures.save_figure(built[4], folder / "study.png", dpi=50)
    reporting.plot_plan(plan, folder / "plan.png")
    scene.render_png(the_scene, folder / "scene.png")
    figures.landing_map(grid, rms, SIZE_PX, SPACING_M, sector(), "chain", folder / "landing.png")
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
    assert [len(fig.axes) for fig in built] == [1, 1, 1, 1, 2, 2, 1, 2]  # the map's colour bar is an axes
    assert matplotlib.get_backend() == "svg"
    assert dict(matplotlib.rcParams) == rc_before
    assert plt.get_fignums() == open_before  # nothing registered with pyplot, nothing left open
    saved = sorted(p.name for p in tmp_path.iterdir())
    names = ("hist", "points", "methods", "residuals", "study", "plan", "scene", "landing")
    assert saved == sorted(f"{n}.png" for n in names)
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


# --- the predicted landing error map -----------------------------------------------------------------
def landing_map_parts(method: str = "chain", with_sector: bool = True):
    """The map's figure, its image, the plotted ``(H, W)`` array (``[v, u]``) and its colour bar's axes."""
    from brachycal.reporting.figures import landing_map_figure

    grid, rms = linear_map()
    fig = landing_map_figure(grid, rms, SIZE_PX, SPACING_M, sector() if with_sector else None, method)
    ax, bar = fig.axes
    (image,) = ax.get_images()
    return fig, ax, image, image.get_array(), bar


def test_the_map_is_labelled_in_the_images_own_axes_and_units_and_names_its_calibration():
    _, ax, image, plotted, bar = landing_map_parts()
    assert ax.get_xlabel() == "u (px)"
    assert ax.get_ylabel() == "v (px, depth: downward)"
    assert bar.get_ylabel() == "predicted landing error, RMS (mm)"
    assert "Whole chain calibration" in ax.get_title() and "imaging sector" in ax.get_title()
    assert plotted.shape == (SIZE_PX[1], SIZE_PX[0])  # one value per pixel, rows are v
    top, bottom = ax.get_ylim()
    assert top > bottom  # v grows downward: row 0 (the transducer) at the top
    left, right, low, high = image.get_extent()
    assert (left, right, low, high) == (-0.5, SIZE_PX[0] - 0.5, SIZE_PX[1] - 0.5, -0.5)  # pixel centres on integers
    _, ax, _, _, _ = landing_map_parts("kabsch")
    assert "Kabsch calibration" in ax.get_title()


def test_outside_the_sector_the_map_is_masked_and_has_no_colour():
    _, _, image, plotted, _ = landing_map_parts()
    # Outside by hand: the corner (0, 0) lies 90° from the depth axis (the sector opens ±60°); the
    # pixel (540, 369) lies 70.11 mm below the apex, (540, 368) 69.92 mm (inside).
    for u, v in ((0, 0), (SIZE_PX[0] - 1, 0), (0, SIZE_PX[1] - 1), (SIZE_PX[0] - 1, SIZE_PX[1] - 1), (540, 369)):
        assert plotted.mask[v, u], (u, v)
        assert image.to_rgba(plotted)[v, u, 3] == 0.0, (u, v)  # transparent
    assert not plotted.mask[368, 540]
    # At 60° from the depth axis (the sector's side), 30 mm from the apex: just inside, just outside.
    for angle_deg, inside in ((59.0, True), (61.0, False)):
        d = 0.030 / SPACING_M[0] * np.array([np.sin(np.radians(angle_deg)), np.cos(np.radians(angle_deg))])
        u, v = np.round(np.array([540.0, 0.0]) + d).astype(int)
        assert plotted.mask[v, u] == (not inside), angle_deg
    # The masked share is the image's area outside the sector: a 70 mm, 120° sector is pi/3 * 368.4² px²
    # of the 1080 x 720 px image.
    expected = 1 - np.pi / 3 * (0.070 / SPACING_M[0]) ** 2 / (SIZE_PX[0] * SIZE_PX[1])
    assert plotted.mask.mean() == pytest.approx(expected, abs=0.005)


def test_inside_the_sector_every_pixel_has_its_predicted_value():
    _, _, image, plotted, _ = landing_map_parts()
    # The sector's centre: on its axis, about half its 368 px depth down (a grid node of the map).
    centre = (540, 180)
    assert plotted[centre[1], centre[0]] == pytest.approx(rms_at(np.array(centre))[0], rel=1e-9)
    assert image.to_rgba(plotted)[centre[1], centre[0], 3] == 1.0  # opaque
    v, u = np.nonzero(~plotted.mask)
    assert np.allclose(plotted[v, u], rms_at(np.column_stack([u, v])), rtol=1e-9)  # between nodes too
    low, high = image.get_clim()  # the colours span the sector's values, not the blank part's
    assert low == pytest.approx(plotted.min()) and high == pytest.approx(plotted.max())
    assert high < rms_at(np.array([SIZE_PX[0] - 1, SIZE_PX[1] - 1]))[0]


def test_without_a_stated_sector_the_whole_image_is_coloured_and_the_title_says_so():
    _, ax, _, plotted, _ = landing_map_parts(with_sector=False)
    assert not np.ma.getmaskarray(plotted).any()
    assert "the session states no sector" in ax.get_title()


def test_a_map_that_is_not_a_regular_grid_is_refused():
    from brachycal.reporting.figures import landing_map_raster

    grid, rms = linear_map()
    with pytest.raises(ValueError, match="not a regular grid"):
        landing_map_raster(grid[1:], rms[1:], SIZE_PX, SPACING_M, sector())
