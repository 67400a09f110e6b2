"""``brachycal design``: compare sample designs by predicted targeting error and robot time."""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np

from brachycal.cli.common import progress_bar
from brachycal.files import OutputSet, atomic_open
from brachycal.model import Robot
from brachycal.simulation.design import DESIGNS, MECHANICAL_MINUTES, SECONDS_PER_SAMPLE, evaluate_design
from brachycal.validate import MAX_SEEDS, bounded_int, name_list

HELP = "compare sample designs (4x4x4, 3x3x3, random, optimal) by predicted targeting error per robot minute"
DESCRIPTION = """\
For each design, plans its poses, simulates a session on the digital twin, calibrates it with the
whole-chain method, and reports the predicted RMS landing error over the prostate cube (from the
calibration's covariance), the actual one against the twin's truth, and the robot time (5 min
mechanical part + 10 s per image sample + planned motion at 25% speed). 'information per minute'
is 1 / (predicted RMS^2 x minutes): higher is a better use of the robot's time.

example:
  brachycal design --out design --seeds 3
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "design", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder (design.csv)")
    seeds = bounded_int(low=1, high=MAX_SEEDS)
    parser.add_argument(
        "--seeds", type=seeds, default=3, help=f"simulated sessions per design, {seeds.rule} (default 3)"
    )
    parser.add_argument(
        "--designs",
        type=name_list(DESIGNS),
        default=",".join(DESIGNS),
        help=f"comma-separated subset of: {', '.join(DESIGNS)}",
    )
    parser.add_argument("--force", action="store_true", help="replace existing outputs")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    designs = args.designs  # checked by argparse: known, none empty, no repeats
    out = Path(args.out)
    with OutputSet(force=args.force) as outputs:
        staged = outputs.claim(out / "design.csv", make_parents=True)
        robot = Robot.load()
        rows = []
        with progress_bar(len(designs) * args.seeds, "designs", args.quiet) as bar:
            for design in designs:
                for seed in range(args.seeds):
                    rows.append(evaluate_design(robot, design, seed))
                    bar.update(1)
        with atomic_open(staged) as handle:
            writer = csv.DictWriter(handle, fieldnames=list(rows[0]), lineterminator="\n")
            writer.writeheader()
            writer.writerows(rows)
    print(f"time model: {MECHANICAL_MINUTES:g} min mechanical + {SECONDS_PER_SAMPLE:g} s per sample + motion")
    print(
        f"{'design':<12} {'samples':>7} {'minutes':>8} {'predicted RMS (mm)':>19} {'actual RMS (mm)':>16} "
        f"{'information/min':>16}"
    )
    for design in designs:
        group = [r for r in rows if r["design"] == design]
        mean = {
            k: float(np.mean([r[k] for r in group]))
            for k in ("robot_minutes", "predicted_rms_mm", "actual_rms_mm", "information_per_minute")
        }
        print(
            f"{design:<12} {group[0]['samples']:>7} {mean['robot_minutes']:>8.1f} {mean['predicted_rms_mm']:>19.3f} "
            f"{mean['actual_rms_mm']:>16.3f} {mean['information_per_minute']:>16.2f}"
        )
    print(f"wrote {out / 'design.csv'}")
    return 0
