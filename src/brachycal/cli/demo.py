"""``brachycal demo``: the main job on the bundled example — a full calibration on the digital twin.

Simulates a session with the paper's set-up (or loads the committed example), calibrates it
exactly as a lab would (from the session files), prints Tables I and II, and next to them the
end-to-end targeting error against the truth, then writes a report folder.
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

import numpy as np

from brachycal.calibration import METHODS, calibrate, write_result
from brachycal.calibration.image_to_probe import METHOD_LABELS
from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.sequential import loo_points
from brachycal.data.session import read_session
from brachycal.files import bundled
from brachycal.model import Robot
from brachycal.reporting import table_i, table_ii, table_iii, targeting_table
from brachycal.reporting.figures import error_histogram, method_comparison, points_3d
from brachycal.simulation.nwire_twin import NWireSimConfig, tracker_route
from brachycal.simulation.targeting import targeting_error
from brachycal.simulation.twin import TwinConfig, simulate
from brachycal.simulation.twin_files import read_twin, write_twin

HELP = "calibrate a simulated session (digital twin) and compare with the truth"
DESCRIPTION = """\
The main job on the bundled example: a digital twin of a calibration session with the paper's
set-up (SDA10F with a slightly different physical geometry, tools off their nominal frames,
encoder noise, jog error at the touches, 1 px annotation noise, the needle tip within the beam's
thickness, water's speed of sound), calibrated from its session files. Prints Table I, Table II
and the end-to-end targeting error against the truth, and writes DIR/session (the session and
its truth), DIR/result.json and DIR/report (figures and per-sample residuals). Table III compares,
on the same simulated robot, the tracker route: an N-wire phantom calibration with an optical
tracker (0.25 mm per marker) and a hand-eye calibration of the probe's marker.

examples:
  brachycal demo                      simulate with seed 0 (= examples/twin_session)
  brachycal demo --seed 7             another simulated session
  brachycal demo --example            calibrate the committed examples/twin_session
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "demo", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", default="demo_output", metavar="DIR", help="output folder (default demo_output)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the simulated session (default 0)")
    parser.add_argument("--example", action="store_true", help="use the committed examples/twin_session")
    parser.add_argument("--targets", type=int, default=50, help="targets for the targeting error (default 50)")
    parser.set_defaults(run=run)


def _mm(v: np.ndarray) -> str:
    return f"{np.linalg.norm(v) * 1e3:.3f} mm"


def run(args: argparse.Namespace) -> int:
    start = time.perf_counter()
    robot = Robot.load()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.example:
        twin = read_twin(bundled("examples", "twin_session"), robot)
        origin = "the committed example examples/twin_session"
    else:
        twin = simulate(robot, TwinConfig(seed=args.seed))
        origin = f"a simulated session (seed {args.seed})"
    c = twin.config
    print(f"brachycal demo: the paper's calibration on {origin}\n")
    print(
        f"twin: {len(twin.session.sample_ids)} planned sample poses in a {c.spec.edge_m * 1e3:.0f} mm cube, "
        f"{c.trials} touches per tool and reference tip"
    )
    print(
        f"      physical robot off its URDF (joint origins {c.link_offset_sd_m * 1e3:.2f} mm / "
        f"{np.degrees(c.link_tilt_sd_rad):.3f} deg SD), tools ~{c.tool_offset_sd_m * 1e3:.0f} mm / "
        f"{np.degrees(c.tool_tilt_sd_rad):.0f} deg off nominal, encoder {c.encoder_sd_rad:g} rad, "
        f"jog {c.jog_sd_m * 1e3:.2f} mm"
    )
    print(
        f"      annotation {c.annotation_sd_px:g} px, needle tip within {c.beam_thickness_m / 2 * 1e3:.1f} mm of the "
        f"image plane, sound {c.sound_speed_m_s:.0f} m/s in water (scanner assumes 1540: depths read "
        f"{(1 / c.axial_scale - 1) * 100:.1f}% long)"
    )
    session_dir = write_twin(twin, out / "session", force=True)
    session = read_session(session_dir, robot)
    result = calibrate(session, robot)
    write_result(result, out / "result.json", force=True)
    print(f"      session and truth in {session_dir}, result in {out / 'result.json'}\n")
    print(table_i(result))
    print()
    print(table_ii(result))

    targeting = {
        m: targeting_error(twin, result.T_ER_Ntip, result.T_EL_Ptip, result.image[m], args.targets) for m in METHODS
    }
    print()
    print(targeting_table({m: t.stats for m, t in targeting.items()}, args.targets))
    route = tracker_route(twin, NWireSimConfig(seed=twin.config.seed))
    via_tracker = targeting_error(twin, result.T_ER_Ntip, route.T_EL_marker, route.image, args.targets)
    print()
    print(
        table_iii(
            {
                "N-wire phantom + optical tracker (hand-eye)": via_tracker.stats,
                **{METHOD_LABELS[m]: targeting[m].stats for m in ("icp", "kabsch", "horn", "scaled_uv")},
            },
            args.targets,
        )
    )
    truth = twin.truth
    print("\nsecondary, transforms against the truth (a calibration rightly absorbs part of the robot's own error):")
    print(
        f"  needle tip {_mm(result.T_ER_Ntip[:3, 3] - truth.T_ER_Ntip[:3, 3])}, "
        f"probe tip {_mm(result.T_EL_Ptip[:3, 3] - truth.T_EL_Ptip[:3, 3])}"
    )
    for method in ("kabsch", "scaled_uv"):
        image = result.image[method]
        chain = result.T_EL_Ptip @ image.T_Ptip_I
        chain_true = truth.T_EL_Ptip @ truth.T_Ptip_I
        centre = np.array([540 * truth.spacing_m[0], 221 * truth.spacing_m[1], 0.0, 1.0])
        centre_cal = np.array([540 * image.spacing_m[0], 221 * image.spacing_m[1], 0.0, 1.0])
        print(
            f"  {method:9s} image centre on the left flange {_mm((chain @ centre_cal - chain_true @ centre)[:3])}, "
            f"spacing {image.spacing_m[0] * 1e3:.4f} x {image.spacing_m[1] * 1e3:.4f} mm/px "
            f"(true {truth.spacing_m[0] * 1e3:.4f} x {truth.spacing_m[1] * 1e3:.4f})"
        )

    report = out / "report"
    report.mkdir(exist_ok=True)
    p_real, p_cal = loo_points(session, robot, result, "icp")
    figures = [
        points_3d(p_real, p_cal, report / "fig10_points.png", "Fig. 10 (e): real and calibrated points (ICP, LOO)"),
        error_histogram(
            ErrorStats.between(p_real, p_cal), report / "fig11_loo_histogram.png", "Fig. 11: leave-one-out errors (ICP)"
        ),
        method_comparison(
            {m: t.stats for m, t in targeting.items()},
            report / "targeting_errors.png",
            f"End-to-end targeting error, {args.targets} targets",
        ),
    ]
    with (report / "residuals.csv").open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["sample", "u_px", "v_px", "out_of_plane_mm", "outlier", *(f"loo_{m}_mm" for m in METHODS)])
        for k, sample in enumerate(session.sample_ids):
            writer.writerow(
                [
                    sample,
                    f"{session.uv_px[k, 0]:.3f}",
                    f"{session.uv_px[k, 1]:.3f}",
                    f"{twin.out_of_plane_m[k] * 1e3:.3f}",
                    int(twin.outlier[k]),
                    *(f"{result.loocv[m].errors_m[k] * 1e3:.4f}" for m in METHODS),
                ]
            )
    print(f"\nreport: {', '.join(str(f) for f in figures)}, {report / 'residuals.csv'}")
    print(f"done in {time.perf_counter() - start:.1f} s")
    return 0
