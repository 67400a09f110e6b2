"""``brachycal design``: compare sample designs by predicted targeting error and robot time."""

from __future__ import annotations

import argparse
from pathlib import Path

from brachycal.cli.common import add_robot_option, load_robot, progress_bar
from brachycal.cli.option_types import bounded_int, name_list
from brachycal.cli.plan.excitation import add_excitation_minutes_option
from brachycal.validate import MAX_SEEDS

HELP = "compare sample designs (4x4x4, 3x3x3, random, optimal) by predicted targeting error per robot minute"
DESCRIPTION = """\
For each design, plans its poses, simulates a session on the digital twin, calibrates it with the
whole-chain method, and reports the predicted RMS landing error over the prostate cube (from the
calibration's covariance), the actual one against the twin's truth, and the robot time (5 min
mechanical part + 10 s per image sample + planned motion at 25% speed). 'information per minute'
is 1 / (predicted RMS^2 x minutes): higher is a better use of the robot's time.

With --robot-error LEVEL (real-arm, worn; the twin's robot off its URDF): instead, the 4x4x4
design plus excitation poses (brachycal plan excitation, --excitation-minutes of extra robot time)
on twins at that level: per seed, the predicted RMS landing error and the targeting and held-out
targeting MAE with the robot identified on the session alone, on the session plus the excitation
poses, on the session plus as many plain repeats of their source poses (is it the new
configurations?) and of session samples drawn at random (is it the choice, or only more data?),
and the extra robot minutes.

example:
  brachycal design --out design --seeds 3
  brachycal design --out design --robot-error worn --seeds 6
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from brachycal.simulation.settings import DESIGNS, ROBOT_ERROR_LEVELS  # lazy: start-up (the command's run only)

    parser = sub.add_parser(
        "design", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder (design.csv)")
    add_robot_option(parser)
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
    parser.add_argument(
        "--robot-error",
        choices=tuple(level for level in ROBOT_ERROR_LEVELS if level != "well-built"),
        help="evaluate excitation poses on twins with this robot error instead (see below)",
    )
    add_excitation_minutes_option(parser, "with --robot-error")
    parser.add_argument("--force", action="store_true", help="replace existing outputs")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from brachycal.io import OutputSet, write_csv  # lazy: start-up (the command's run only)
    from brachycal.reporting import design_table  # lazy: start-up (the command's run only)
    from brachycal.studies import compare_designs  # lazy: start-up (the command's run only)

    out = Path(args.out)
    if args.robot_error is not None:
        return _run_excitation(args, out)
    with OutputSet(force=args.force) as outputs:
        staged = outputs.claim(out / "design.csv", make_parents=True)
        with progress_bar(len(args.designs) * args.seeds, "designs", args.quiet, unit="twin") as bar:
            rows = compare_designs(load_robot(args), args.designs, args.seeds, progress=bar.update)
        write_csv(staged, rows)
    print(design_table(rows))
    print(f"wrote {out / 'design.csv'}")
    return 0


#: Columns of the --robot-error table: (row key, heading, format).
_EXCITATION_COLUMNS = (
    ("seed", "seed", "{}"),
    ("touches", "touches", "{}"),
    ("samples", "samples", "{}"),
    ("minutes", "extra min", "{:.2f}"),
    ("predicted_rms_before_mm", "pred. RMS before", "{:.4f}"),
    ("predicted_rms_after_mm", "after", "{:.4f}"),
    ("target_mae_before_mm", "MAE before", "{:.4f}"),
    ("target_mae_after_mm", "after", "{:.4f}"),
    ("target_mae_repeats_mm", "repeats", "{:.4f}"),
    ("target_mae_random_repeats_mm", "random", "{:.4f}"),
    ("held_out_mae_before_mm", "held-out before", "{:.4f}"),
    ("held_out_mae_after_mm", "after", "{:.4f}"),
    ("held_out_mae_repeats_mm", "repeats", "{:.4f}"),
    ("held_out_mae_random_repeats_mm", "random", "{:.4f}"),
)


def _run_excitation(args: argparse.Namespace, out: Path) -> int:
    import numpy as np  # lazy: start-up (the command's run only)

    from brachycal.errors import InputError  # lazy: start-up (the command's run only)
    from brachycal.io import OutputSet, write_csv  # lazy: start-up (the command's run only)
    from brachycal.simulation.settings import DESIGNS  # lazy: start-up (the command's run only)
    from brachycal.studies.design import compare_excitation  # lazy: start-up (the command's run only)

    if list(args.designs) != list(DESIGNS):
        raise InputError("--robot-error evaluates the 4x4x4 design with excitation poses: do not pass --designs")
    robot = load_robot(args)
    with OutputSet(force=args.force) as outputs:
        staged = outputs.claim(out / "design.csv", make_parents=True)
        with progress_bar(args.seeds, "excitation", args.quiet, unit="twin") as bar:
            rows = compare_excitation(robot, args.robot_error, args.seeds, args.excitation_minutes, progress=bar.update)
        write_csv(staged, rows)
    widths = [max(len(h), 7) for _, h, _ in _EXCITATION_COLUMNS]
    print(f"grid 4x4x4 + excitation poses, {args.robot_error} twin, MAE and RMS in mm:")
    print("  ".join(h.rjust(w) for (_, h, _), w in zip(_EXCITATION_COLUMNS, widths, strict=True)))
    for row in rows:
        print("  ".join(f.format(row[k]).rjust(w) for (k, _, f), w in zip(_EXCITATION_COLUMNS, widths, strict=True)))
    means = ["mean".rjust(widths[0])]
    for (key, _, form), width in zip(_EXCITATION_COLUMNS[1:], widths[1:], strict=True):
        mean = float(np.mean([row[key] for row in rows]))
        means.append((f"{mean:.1f}" if form == "{}" else form.format(mean)).rjust(width))
    print("  ".join(means))
    print(f"wrote {out / 'design.csv'}")
    return 0
