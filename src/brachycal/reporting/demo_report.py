"""The demo's text and report folder (:class:`~brachycal.studies.demo.DemoRun` rendered).

:func:`demo_text` is what ``brachycal demo`` prints: the twin's set-up, Tables I and II, the
end-to-end targeting error of every method, Table III (the tracker route against the fusion
methods) and, as secondary figures, the calibrated transforms against the truth.
:func:`write_demo_report` writes the figures and the per-sample residuals
(:data:`DEMO_REPORT_FILES`).
"""

from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np

from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.sequential.image_to_probe import METHOD_LABELS, METHODS
from brachycal.imaging.pixels import SCANNER_SOUND_SPEED_M_S
from brachycal.io import OutputSet, atomic_open, output_set
from brachycal.reporting.figures import error_histogram, method_comparison, points_3d
from brachycal.reporting.tables import table_i, table_ii, table_iii, targeting_table
from brachycal.studies.demo import TRUTH_METHODS, DemoRun

#: The files :func:`write_demo_report` writes into its folder.
DEMO_REPORT_FILES = ("fig10_points.png", "fig11_loo_histogram.png", "targeting_errors.png", "residuals.csv")
#: The methods Table III sets against the tracker route.
TABLE_III_METHODS = ("icp", "kabsch", "horn", "scaled_uv")


def _mm(v: np.ndarray) -> str:
    return f"{np.linalg.norm(v) * 1e3:.3f} mm"


def demo_text(run: DemoRun) -> str:
    """What ``brachycal demo`` prints about ``run`` (lengths in mm, angles in degrees)."""
    twin, result, c = run.twin, run.result, run.twin.config
    lines = [
        f"brachycal demo: the paper's calibration on {run.origin}",
        f"robot: {twin.nominal.rig.name} ({twin.nominal.rig.summary})",
        "",
        f"twin: {len(twin.session.sample_ids)} planned sample poses in a {c.spec.edge_m * 1e3:.0f} mm cube, "
        f"{c.trials} touches per tool and reference tip",
        f"      physical robot off its URDF (joint origins {c.link_offset_sd_m * 1e3:.2f} mm / "
        f"{np.degrees(c.link_tilt_sd_rad):.3f} deg SD), tools ~{c.tool_offset_sd_m * 1e3:.0f} mm / "
        f"{np.degrees(c.tool_tilt_sd_rad):.0f} deg off nominal, encoder {c.encoder_sd_rad:g} rad, "
        f"jog {c.jog_sd_m * 1e3:.2f} mm",
        f"      annotation {c.annotation_sd_px:g} px, needle tip within {c.beam_thickness_m / 2 * 1e3:.1f} mm of the "
        f"image plane, sound {c.sound_speed_m_s:.0f} m/s in water (scanner assumes "
        f"{SCANNER_SOUND_SPEED_M_S:.0f}: depths read {(1 / c.axial_scale - 1) * 100:.1f}% long)",
        "",
        table_i(result),
        "",
        table_ii(result),
        "",
        targeting_table({m: t.stats for m, t in run.targeting.items()}, run.n_targets),
        "",
        table_iii(
            {
                "N-wire phantom + optical tracker (hand-eye)": run.tracker.stats,
                **{METHOD_LABELS[m]: run.targeting[m].stats for m in TABLE_III_METHODS if m in run.targeting},
            },
            run.n_targets,
        ),
    ]
    tracking = run.tracking
    lines.append(
        f"  tracker route: {tracking.tracker_accuracy_m * 1e3:.2f} mm RMS per marker "
        f"({tracking.tracker_jitter_m * 1e3:.2f} mm of it jitter), {tracking.tracker_frames} frames averaged per "
        f"still pose,\n  {tracking.calibration_frames} N-wire images, {tracking.hand_eye_poses} hand-eye poses; "
        "one seed: the spread over seeds is in the documentation (Validation, Table III)"
    )
    truth = twin.truth
    needle, probe = run.tip_errors_m()
    lines += [
        "",
        "secondary, transforms against the truth (a calibration rightly absorbs part of the robot's own error):",
        f"  needle tip {_mm(needle)}, probe tip {_mm(probe)}",
    ]
    for method in (m for m in TRUTH_METHODS if m in result.image):
        spacing = result.image[method].spacing_m
        lines.append(
            f"  {method:9s} image centre on the probe flange {_mm(run.image_centre_error_m(method))}, "
            f"spacing {spacing[0] * 1e3:.4f} x {spacing[1] * 1e3:.4f} mm/px "
            f"(true {truth.spacing_m[0] * 1e3:.4f} x {truth.spacing_m[1] * 1e3:.4f})"
        )
    return "\n".join(lines)


def write_demo_report(
    run: DemoRun, folder: str | os.PathLike[str], *, force: bool = False, outputs: OutputSet | None = None
) -> list[Path]:
    """Write the demo's figures and residuals into ``folder`` (:data:`DEMO_REPORT_FILES`).

    Fig. 10 (real and calibrated points, the run's ``figure_method``'s leave-one-out: normally
    :data:`~brachycal.studies.demo.FIGURE_METHOD`), Fig. 11 (its error histogram), the
    targeting error per method, and ``residuals.csv``: per sample its pixel, the needle tip's
    distance from the image plane (mm), whether its annotation is a gross outlier, and each
    method's leave-one-out error (mm; a method that refused the session has no column).
    All or nothing, as :func:`~brachycal.io.output_set` says; returns the final paths.
    """
    folder = Path(folder)
    label = METHOD_LABELS[run.figure_method]
    with output_set(outputs, force=force) as out:
        staged = {name: out.path(folder / name, make_parents=True) for name in DEMO_REPORT_FILES}
        points_3d(
            run.loo_real_m,
            run.loo_cal_m,
            staged["fig10_points.png"],
            f"Fig. 10 (e): real and calibrated points ({label}, LOO)",
        )
        error_histogram(
            ErrorStats.between(run.loo_real_m, run.loo_cal_m),
            staged["fig11_loo_histogram.png"],
            f"Fig. 11: leave-one-out errors ({label})",
        )
        method_comparison(
            {m: t.stats for m, t in run.targeting.items()},
            staged["targeting_errors.png"],
            f"End-to-end targeting error, {run.n_targets} targets",
        )
        session, twin, result = run.session, run.twin, run.result
        methods = [m for m in METHODS if m in result.loocv]
        with atomic_open(staged["residuals.csv"]) as handle:
            writer = csv.writer(handle)
            writer.writerow(["sample", "u_px", "v_px", "out_of_plane_mm", "outlier", *(f"loo_{m}_mm" for m in methods)])
            for k, sample in enumerate(session.sample_ids):
                writer.writerow(
                    [
                        sample,
                        f"{session.uv_px[k, 0]:.3f}",
                        f"{session.uv_px[k, 1]:.3f}",
                        f"{twin.out_of_plane_m[k] * 1e3:.3f}",
                        int(twin.outlier[k]),
                        *(f"{result.loocv[m].errors_m[k] * 1e3:.4f}" for m in methods),
                    ]
                )
    return [folder / name for name in DEMO_REPORT_FILES]
