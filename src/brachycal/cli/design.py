"""``brachycal design``: compare sample designs by predicted targeting error and robot time."""

from __future__ import annotations

import argparse
from pathlib import Path

from brachycal.cli.common import progress_bar
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
    from brachycal.simulation.settings import DESIGNS

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
    from brachycal.files import OutputSet, write_csv
    from brachycal.model import Robot
    from brachycal.reporting import design_table
    from brachycal.simulation import compare_designs

    out = Path(args.out)
    with OutputSet(force=args.force) as outputs:
        staged = outputs.claim(out / "design.csv", make_parents=True)
        with progress_bar(len(args.designs) * args.seeds, "designs", args.quiet) as bar:
            rows = compare_designs(Robot.load(), args.designs, args.seeds, progress=bar.update)
        write_csv(staged, rows)
    print(design_table(rows))
    print(f"wrote {out / 'design.csv'}")
    return 0
