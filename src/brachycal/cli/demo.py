"""``brachycal demo``: the main job on the bundled example — a full calibration on the digital twin.

Simulates a session with the paper's set-up (or loads the committed example), calibrates it
exactly as a lab would (from the session files), prints Tables I and II, and next to them the
end-to-end targeting error against the truth, then writes a report folder.
"""

from __future__ import annotations

import argparse
import csv
import os
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from brachycal.calibration import METHODS, calibrate, write_result
from brachycal.calibration.image_to_probe import METHOD_LABELS
from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.sequential import loo_points
from brachycal.data.session import FILES as SESSION_FILES
from brachycal.data.session import read_session
from brachycal.files import OutputSet, atomic_open, bundled
from brachycal.model import Robot
from brachycal.reporting import table_i, table_ii, table_iii, targeting_table
from brachycal.reporting.figures import error_histogram, method_comparison, points_3d
from brachycal.simulation.nwire_twin import NWireSimConfig, tracker_route
from brachycal.simulation.targeting import targeting_error
from brachycal.simulation.twin import TwinConfig, simulate
from brachycal.simulation.twin_files import TWIN_FILES, read_twin, write_twin
from brachycal.validate import MAX_TARGETS, bounded_int, seed

HELP = "calibrate a simulated session (digital twin) and compare with the truth"
DESCRIPTION = """\
The main job on the bundled example: a digital twin of a calibration session with the paper's
set-up (SDA10F with a slightly different physical geometry, tools off their nominal frames,
encoder noise, jog error at the touches, 1 px annotation noise, the needle tip within the beam's
thickness, water's speed of sound), calibrated from its session files. Prints Table I, Table II
and the end-to-end targeting error against the truth, and writes DIR/session (the session and
its truth), DIR/result.json and DIR/report (figures and per-sample residuals). Table III compares,
on the same simulated robot, the tracker route: an N-wire phantom calibration and a hand-eye
calibration of the probe's marker with an optical tracker (NDI Polaris Spectra as in the paper:
0.25 mm RMS per marker, of which 0.1 mm jitter that 20 averaged frames per still pose reduce; wire
echoes from the beam's thickness, phantom print tolerance, landmark registration). One seed varies:
over seeds 0-9 the tracker route lands 0.49 +/- 0.13 mm (MAE, mean +/- SD over seeds), the paper's
Kabsch fusion 0.40 +/- 0.02 mm, the scaled u/v fusion 0.07 +/- 0.01 mm
(python benchmarks/table3.py).

The files are written together when the demo succeeded; an earlier demo's files in DIR are
replaced only with --force.

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
    parser.add_argument("--seed", type=seed, default=0, help=f"seed of the simulated session, {seed.rule} (default 0)")
    parser.add_argument("--example", action="store_true", help="use the committed examples/twin_session")
    targets = bounded_int(low=1, high=MAX_TARGETS)
    parser.add_argument(
        "--targets", type=targets, default=50, help=f"targets for the targeting error, {targets.rule} (default 50)"
    )
    parser.add_argument("--force", action="store_true", help="replace the outputs of an earlier demo in DIR")
    parser.set_defaults(run=run)


def _mm(v: np.ndarray) -> str:
    return f"{np.linalg.norm(v) * 1e3:.3f} mm"


REPORT = ("fig10_points.png", "fig11_loo_histogram.png", "targeting_errors.png", "residuals.csv")


def run(args: argparse.Namespace) -> int:
    start = time.perf_counter()
    out = Path(args.out)
    with OutputSet(force=args.force) as outputs:
        for name in TWIN_FILES:
            outputs.claim(out / "session" / name, make_parents=True)
        outputs.claim(out / "result.json", make_parents=True)
        for name in REPORT:
            outputs.claim(out / "report" / name, make_parents=True)
        _run(args, outputs)
    report = out / "report"
    print(f"\nwrote {out / 'session'} (session and truth), {out / 'result.json'}, {report}: {', '.join(REPORT)}")
    print(f"done in {time.perf_counter() - start:.1f} s")
    return 0


@contextmanager
def _as_written(outputs: OutputSet, session_dir: Path) -> Iterator[Path]:
    """A temporary folder showing the staged session files under their own names (symlinks)."""
    with tempfile.TemporaryDirectory(prefix="brachycal-demo-") as tmp:
        for name in SESSION_FILES:
            os.symlink(outputs.path(session_dir / name).absolute(), Path(tmp) / name)
        yield Path(tmp)


def _run(args: argparse.Namespace, outputs: OutputSet) -> None:
    """The demo; writes the twin's session, the result and the report into ``outputs``."""
    robot = Robot.load()
    out = Path(args.out)
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
    session_dir = out / "session"
    write_twin(twin, session_dir, force=args.force, outputs=outputs)
    # Calibrate from the files as written (the staged ones: the same bytes the folder will hold).
    with _as_written(outputs, session_dir) as folder:
        session = read_session(folder, robot)
    result = calibrate(session, robot)
    write_result(result, outputs.path(out / "result.json"), force=args.force)
    print()
    print(table_i(result))
    print()
    print(table_ii(result))

    targeting = {
        m: targeting_error(twin, result.T_ER_Ntip, result.T_EL_Ptip, result.image[m], args.targets) for m in METHODS
    }
    print()
    print(targeting_table({m: t.stats for m, t in targeting.items()}, args.targets))
    tracking = NWireSimConfig(seed=twin.config.seed)
    route = tracker_route(twin, tracking)
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
    print(
        f"  tracker route: {tracking.tracker_accuracy_m * 1e3:.2f} mm RMS per marker "
        f"({tracking.tracker_jitter_m * 1e3:.2f} mm of it jitter), {tracking.tracker_frames} frames averaged per "
        f"still pose,\n  {tracking.calibration_frames} N-wire images, {tracking.hand_eye_poses} hand-eye poses; "
        "one seed: the spread over seeds is in benchmarks/table3.py"
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
    p_real, p_cal = loo_points(session, robot, result, "icp")
    points_3d(
        p_real,
        p_cal,
        outputs.path(report / "fig10_points.png"),
        "Fig. 10 (e): real and calibrated points (ICP, LOO)",
    )
    error_histogram(
        ErrorStats.between(p_real, p_cal),
        outputs.path(report / "fig11_loo_histogram.png"),
        "Fig. 11: leave-one-out errors (ICP)",
    )
    method_comparison(
        {m: t.stats for m, t in targeting.items()},
        outputs.path(report / "targeting_errors.png"),
        f"End-to-end targeting error, {args.targets} targets",
    )
    with atomic_open(outputs.path(report / "residuals.csv")) as handle:
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
