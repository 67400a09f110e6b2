"""Robot identification from touches on MUKCa's real Franka Panda arms, held-out places first.

Run: ``.venv/bin/python benchmarks/mukca.py [ROBOT [TRAIN]] [--prior MM,DEG[,TILT]] [--compliance JOINTS]``
(default ``panda_2_clean front_center``, prior 0.3 mm / 0.1° per joint (a third figure: the axes'
tilt apart), compliance of joints 2–7
under gravity, masses from example-robot-data's Panda). Needs the MUKCa data (outside data,
``BRACHYCAL_REFERENCE``/``mukca_touches``).

Per place, MUKCa's metric (per socket the mean distance of the ball from its mean, averaged over
the two sockets; and | |p0 − p1| − 50 mm |) for the nominal URDF, brachycal's identification
trained on TRAIN only, and MUKCa's own calibrated URDF (its ``ball_link``) — the same metric on
the same places. The mean over the held-out places comes first, the training place after.
"""

from __future__ import annotations

import os

# One BLAS thread: the problems are small (hundreds of rows), and a threaded BLAS on a shared
# machine spends 20 times longer waiting than computing.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from brachycal.calibration.robot.arm_fit import gravity_moments
from brachycal.calibration.robot.defaults import TOUCHES_ACCURACY
from brachycal.calibration.robot.touches import (
    TOUCH_SETTINGS,
    TouchPlace,
    choose_touch_setting,
    identify_touches,
    read_places,
    setting_prior,
    touch_scatter,
)
from brachycal.calibration.robot_accuracy import RobotAccuracy
from brachycal.model.description_file import example_robot_data_share
from brachycal.model.robot import Robot

ROOT = Path(__file__).parents[1]
DATA = Path(os.environ.get("BRACHYCAL_REFERENCE") or ROOT.parent / "shared" / "reference") / "mukca_touches"
FLANGE = "panda_link8"
CALIBRATED = {"panda_2_clean": "panda_2", "panda_3": "panda_3", "panda_3_bis": "panda_3"}


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("robot", nargs="?", default="panda_2_clean")
    parser.add_argument("train", nargs="?", default=None, help="training place(s), comma-separated")
    parser.add_argument(
        "--prior",
        default="0.3,0.1",
        help="per-joint prior SD: millimetres,degrees[,tilt degrees] (the tilt: about the axes across the joint's)",
    )
    parser.add_argument(
        "--compliance",
        default="2z,3z,4z,5z,6z,7z",
        help="compliance terms: joint number (1-based) and the axes of its frame it turns about; 'none'",
    )
    parser.add_argument("--compliance-sd", type=float, default=float("inf"), help="prior SD, rad/(N m)")
    parser.add_argument(
        "--evidence", action="store_true", help="choose the priors by the training touches' evidence (start: --prior)"
    )
    parser.add_argument("--no-distance", action="store_true", help="do not use the 50 mm between the sockets")
    parser.add_argument(
        "--choose",
        type=int,
        metavar="K",
        help="every shared robot, each place in turn with the K - 1 after it the training places: the setting "
        "chosen by "
        "cross-validation inside them (K = 1: over the postures; K >= 2: leave one place out) against the "
        "defaults, on the written URDF (geometry only), judged on the robot's other places",
    )
    parser.add_argument("--robots", help="with --choose: these robots only (comma-separated; default all)")
    args = parser.parse_args(argv)
    if args.choose is not None:
        return choose_all(args.choose, args.robots.split(",") if args.robots else None)
    train = (args.train or ("front_center" if args.robot == "panda_2_clean" else "frontcenter")).split(",")
    mm, deg, *tilt = (float(v) for v in args.prior.split(","))
    compliant = tuple(
        (int(term[0]) - 1, "xyz".index(a)) for term in args.compliance.split(",") if term != "none" for a in term[1:]
    )

    if not (DATA / "data" / args.robot).is_dir():
        print(f"skipped: {DATA / 'data' / args.robot} is not there (MUKCa's public data)", file=sys.stderr)
        return 1
    nominal = Robot.load(DATA / "urdf" / "panda.urdf")
    calibrated = Robot.load(DATA / "calibrated_urdf" / CALIBRATED[args.robot] / "panda_calibrated.urdf")
    folders = sorted(p for p in (DATA / "data" / args.robot).iterdir() if p.is_dir())
    places = {p.name: p for p in read_places(nominal, FLANGE, folders, {(0, 1): 0.05})}
    if compliant:
        dynamics = Robot.load(example_robot_data_share() / "robots" / "panda_description" / "urdf" / "panda.urdf")
        places = {
            n: TouchPlace(
                p.name, p.touches, p.distances, tuple(gravity_moments(dynamics, nominal, Q) for Q in p.touches)
            )
            for n, p in places.items()
        }
    fit_places = [
        places[n] if not args.no_distance else TouchPlace(n, places[n].touches, {}, places[n].moments) for n in train
    ]
    tip0 = nominal.transform(FLANGE, "ball_link", np.zeros(nominal.nq))[:3, 3]
    tip_mukca = calibrated.transform(FLANGE, "ball_link", np.zeros(calibrated.nq))[:3, 3]
    start = time.perf_counter()
    result = identify_touches(
        nominal,
        fit_places,
        FLANGE,
        RobotAccuracy(mm * 1e-3, float(np.radians(deg)), tilt_sd_rad=float(np.radians(tilt[0])) if tilt else None),
        tip=tip0,
        selection="chain",
        compliant=compliant,
        compliance_sd=args.compliance_sd,
        prior="evidence" if args.evidence else "stated",
    )
    seconds = time.perf_counter() - start
    robot = result.robot(nominal)
    chosen = result.fit.accuracy
    assert chosen is not None
    print(
        f"{args.robot}: trained on {','.join(train)} in {seconds:.1f} s; "
        f"prior {'chosen by evidence: ' if args.evidence else ''}"
        f"{chosen.translation_sd_m * 1e3:.3f} mm / {np.degrees(chosen.rotation_sd_rad):.3f} deg"
        f"{f' / tilt {np.degrees(chosen.tilt_sd_rad):.3f} deg' if chosen.tilt_sd_rad is not None else ''}"
        f"{f', compliance {result.compliance_sd[0]:.2e} rad/(N m)' if len(result.compliance_sd) else ''}; "
        f"compliance {args.compliance}; "
        f"touch noise {result.fit.sigma['touch'] * 1e3:.3f} mm; tip {np.round(result.tip * 1e3, 3)} mm"
    )
    print(f"{'place':14s} {'nominal':>16s} {'brachycal':>16s} {'MUKCa URDF':>16s}   (scatter mm, |d-50| mm)")
    rows = {}
    for name, place in places.items():
        a = touch_scatter(nominal, place, FLANGE, tip0)
        b = touch_scatter(robot, place, FLANGE, result.tip, result.compliant, result.compliance)
        c = touch_scatter(calibrated, place, FLANGE, tip_mukca)
        rows[name] = [(s.mean_scatter_m * 1e3, s.distance_error_m[(0, 1)] * 1e3) for s in (a, b, c)]
    held = [n for n in rows if n not in train]
    for name in [*held, *train]:
        cells = "".join(f" {s:7.3f} {d:7.3f} " for s, d in rows[name])
        print(f"{name:14s}{cells}{'  (training)' if name in train else ''}")
    means = np.mean([[s for s, _ in rows[n]] for n in held], axis=0)
    worse = [n for n in held if rows[n][1][0] > rows[n][2][0]]
    print(
        f"held-out mean scatter: nominal {means[0]:.3f}  brachycal {means[1]:.3f}  MUKCa URDF {means[2]:.3f} mm; "
        f"places where brachycal > MUKCa: {', '.join(worse) or 'none'}"
    )
    return 0


def choose_all(k: int, only: list[str] | None = None) -> int:
    """Per robot, per set of ``k`` training places: the held-out mean scatter of the written URDF
    (geometry only) with the defaults and with the setting chosen by cross-validation inside the
    training places (over the postures with one place, over the places with more); then per robot
    the chosen-minus-defaults difference, its mean over the training sets and that mean's standard
    error."""
    robots = sorted(p.name for p in (DATA / "data").iterdir() if p.is_dir()) if (DATA / "data").is_dir() else []
    robots = [r for r in robots if only is None or r in only]
    if not robots:
        print(f"skipped: {DATA / 'data'} is not there (MUKCa's public data)", file=sys.stderr)
        return 1
    nominal = Robot.load(DATA / "urdf" / "panda.urdf")
    tip0 = nominal.transform(FLANGE, "ball_link", np.zeros(nominal.nq))[:3, 3]
    accuracy = TOUCHES_ACCURACY
    over = "postures" if k == 1 else "places"
    print(
        f"defaults: prior {accuracy.translation_sd_m * 1e3:.3g} mm / {np.degrees(accuracy.rotation_sd_rad):.3g} deg; "
        f"settings {', '.join(TOUCH_SETTINGS)}; chosen by cross-validation over the training {over}; "
        "written URDF (geometry only); held-out places' mean scatter, mm"
    )
    summary = []
    for name in robots:
        folders = sorted(p for p in (DATA / "data" / name).iterdir() if p.is_dir())
        places = {p.name: p for p in read_places(nominal, FLANGE, folders, {(0, 1): 0.05})}
        print(f"{name}: {'train':30s} {'defaults':>10s} {'chosen':>10s}  setting chosen")
        diffs = []
        names = list(places)
        # Each place in turn with the k - 1 after it (cyclic, sorted): as many training sets as places.
        sets = (
            [tuple(names[(i + j) % len(names)] for j in range(k)) for i in range(len(names))] if k < len(names) else []
        )
        for train in sets:
            start = time.perf_counter()
            held = [p for n, p in places.items() if n not in train]
            fit_places = [places[n] for n in train]
            choice = choose_touch_setting(nominal, fit_places, FLANGE, accuracy, tip=tip0, over=over)
            figures = {}
            for setting in dict.fromkeys((TOUCH_SETTINGS[0], choice.chosen)):
                prior, start_accuracy = setting_prior(setting, accuracy)
                fit = identify_touches(
                    nominal, fit_places, FLANGE, start_accuracy, tip=tip0, selection="chain", prior=prior
                )
                robot = fit.robot(nominal)
                scatter = [touch_scatter(robot, p, FLANGE, fit.tip).mean_scatter_m for p in held]
                figures[setting] = float(np.mean(scatter)) * 1e3
            diffs.append(figures[choice.chosen] - figures[TOUCH_SETTINGS[0]])
            print(
                f"  {','.join(train):36s} {figures[TOUCH_SETTINGS[0]]:10.4f} {figures[choice.chosen]:10.4f}"
                f"  {choice.chosen} ({time.perf_counter() - start:.0f} s)",
                flush=True,
            )
        d = np.array(diffs)
        se = float(np.std(d, ddof=1) / np.sqrt(len(d))) if len(d) > 1 else float("nan")
        summary.append((name, len(d), d.mean(), se))
    print("robot           training sets  chosen - defaults: mean over the training sets ± its SE, mm")
    for name, n, mean, se in summary:
        print(f"{name:16s} {n:13d}  {mean:+.4f} ± {se:.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
