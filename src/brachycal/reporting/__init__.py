"""Reports for people: the paper's tables and figures, the plan figure, the 3D scene, the HTML report.

Tables return text (millimetres and degrees, as their heads say); Tables I and II also come as
data (:class:`StatsTable`, what the HTML report renders as HTML tables). Every figure has a builder that
returns a matplotlib ``Figure`` (``*_figure``; neither touches pyplot, the backend or
``rcParams``) and a function that saves it (:func:`save_figure` and the functions named after the
figure, which write through :mod:`brachycal.io`). The 3D scene (:func:`robot_scene`,
:func:`scene_figure`, :func:`render_png`, :func:`save_glb`) loads trimesh on first use. The
interactive view in the browser (:class:`Viewer` of a :class:`ViewContent`: :func:`poses_content`,
:func:`calibration_content`) is served by viser.
"""

from typing import TYPE_CHECKING

from brachycal._lazy import attach

if TYPE_CHECKING:  # imported on first use (matplotlib ~0.5 s, trimesh ~0.6 s to load)
    from brachycal.reporting.contact_sheet import contact_sheet, contact_sheet_figure
    from brachycal.reporting.demo_report import DEMO_REPORT_FILES, demo_text, write_demo_report
    from brachycal.reporting.figures import (
        error_histogram,
        error_histogram_figure,
        landing_map,
        landing_map_figure,
        landing_map_raster,
        method_comparison,
        method_comparison_figure,
        points_3d,
        points_3d_figure,
        residuals_per_sample,
        residuals_per_sample_figure,
        save_figure,
        study_figure,
    )
    from brachycal.reporting.html_report import CHAIN_REPORT_FILES, REPORT_FILES, report_files, write_report
    from brachycal.reporting.plan_plot import plan_figure, plot_plan
    from brachycal.reporting.scene import TOOL_FRAMES, render_png, robot_scene, save_glb, scene_figure
    from brachycal.reporting.tables import (
        STATS_COLUMNS,
        StatsRow,
        StatsTable,
        chain_summary,
        design_table,
        plan_text,
        study_table,
        table_i,
        table_i_data,
        table_ii,
        table_ii_data,
        table_iii,
        targeting_table,
        uncertainty_table,
    )
    from brachycal.reporting.viewer import ViewContent, Viewer, calibration_content, poses_content

__getattr__, __dir__ = attach(__name__, __file__)


__all__ = [
    "CHAIN_REPORT_FILES",
    "DEMO_REPORT_FILES",
    "REPORT_FILES",
    "STATS_COLUMNS",
    "TOOL_FRAMES",
    "StatsRow",
    "StatsTable",
    "ViewContent",
    "Viewer",
    "calibration_content",
    "chain_summary",
    "contact_sheet",
    "contact_sheet_figure",
    "demo_text",
    "design_table",
    "error_histogram",
    "error_histogram_figure",
    "landing_map",
    "landing_map_figure",
    "landing_map_raster",
    "method_comparison",
    "method_comparison_figure",
    "plan_figure",
    "plan_text",
    "plot_plan",
    "points_3d",
    "points_3d_figure",
    "poses_content",
    "render_png",
    "report_files",
    "residuals_per_sample",
    "residuals_per_sample_figure",
    "robot_scene",
    "save_figure",
    "save_glb",
    "scene_figure",
    "study_figure",
    "study_table",
    "table_i",
    "table_i_data",
    "table_ii",
    "table_ii_data",
    "table_iii",
    "targeting_table",
    "uncertainty_table",
    "write_demo_report",
    "write_report",
]
