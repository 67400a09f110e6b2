"""``brachycal study``: sweep the twin's set-up over seeds; truth error next to LOO figures."""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import TYPE_CHECKING

from brachycal.cli.common import add_robot_option, progress_bar
from brachycal.cli.option_types import bounded_int, name_list, number_list
from brachycal.imaging import SCANNER_SOUND_SPEED_M_S
from brachycal.planning.spec import EDGE_RANGE_M
from brachycal.validate import MAX_GRID_POINTS, MAX_SEEDS, MAX_TARGETS, MAX_WORKERS

if TYPE_CHECKING:
    from brachycal.studies.study import RunParams

HELP = "sweep noise, sample count and grid size on the twin: truth error vs leave-one-out"
DESCRIPTION = """\
Answers "how many samples do we need, and how good is our calibration really": for every
combination of the swept settings and each seed, simulates a session on the digital twin,
calibrates it, and records the leave-one-out figures (what a lab sees) next to the end-to-end
targeting error against the truth (what the clinic needs), both from the sample poses and at
held-out configurations (torso turned 3 deg: postures the calibration never saw).

Any robot with a description (--robot NAME|FILE, docs/robots.md): the twin plans in its
workspace. A robot without a joint shared by both arms (no torso: baxter, ur5_pair) has no
held-out turn: its held-out columns read nan in the CSV files, "no torso" in the table.

Runs go to all local cores (--workers), or to an existing Dask distributed cluster
(--scheduler tcp://host:8786; pip install 'brachycal[cluster]'). Rows are identical to a serial
run (--workers 1) for the same seeds. Writes DIR/runs.csv (one row per run and method),
DIR/summary.csv (mean and SD over seeds) and DIR/study.png.

example:
  brachycal study --out study --points 3,4,5 --annotation-px 0.5,1,2 --seeds 5
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from brachycal.simulation.settings import (  # lazy: start-up (the command's run only)
        MAX_ANNOTATION_SD_PX,
        MAX_OUTLIER_RATE,
        MAX_STUDY_RUNS,
        ROBOT_ERROR_LEVELS,
        STUDY_METHODS,
        WATER_SOUND_SPEED_M_S,
    )

    parser = sub.add_parser(
        "study", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder")
    seeds = bounded_int(low=1, high=MAX_SEEDS)
    parser.add_argument(
        "--seeds",
        type=seeds,
        default=5,
        help=f"repeats per setting, {seeds.rule} (default 5); the whole sweep (seeds x every combination) "
        f"at most {MAX_STUDY_RUNS} simulated sessions",
    )
    points = number_list(kind=int, low=2, high=MAX_GRID_POINTS)
    parser.add_argument(
        "--points",
        type=points,
        default="3,4,5",
        help=f"grid points per axis, {points.rule} (default 3,4,5: 27/64/125 samples)",
    )
    edges = number_list(low=EDGE_RANGE_M[0] * 1e3, high=EDGE_RANGE_M[1] * 1e3, unit="mm")
    parser.add_argument("--edge-mm", type=edges, default="40", help=f"cube edges, {edges.rule} (default 40)")
    noises = number_list(low=0.0, high=MAX_ANNOTATION_SD_PX, unit="px")
    parser.add_argument(
        "--annotation-px",
        type=noises,
        default="0.5,1,2",
        help=f"annotation noise SDs, {noises.rule} (default 0.5,1,2)",
    )
    parser.add_argument(
        "--sound",
        choices=("water", "tissue", "both"),
        default="water",
        help=f"speed of sound: water ({WATER_SOUND_SPEED_M_S:.0f} m/s, default), tissue (= scanner's "
        f"{SCANNER_SOUND_SPEED_M_S:.0f}), or both",
    )
    rates = number_list(low=0.0, high=MAX_OUTLIER_RATE)
    parser.add_argument(
        "--outlier-rate",
        type=rates,
        default="0",
        help=f"gross annotation outlier rates, fractions {rates.rule} (beyond half no robust fit can work; default 0)",
    )
    parser.add_argument(
        "--methods",
        type=name_list(STUDY_METHODS),
        default="kabsch,scaled_uv",
        help="methods: the sequential ones, 'chain', and 'chain+robot' (the chain with the robot identified, "
        "the twin's robot-error level as its prior) (default kabsch,scaled_uv)",
    )
    parser.add_argument(
        "--robot-error",
        type=name_list(tuple(ROBOT_ERROR_LEVELS)),
        default="well-built",
        metavar="LEVEL,...",
        help="how far the twin's robot is off its URDF: well-built (0.03 mm / 0.003 deg per joint, the default), "
        "real-arm (0.1 mm / 0.01 deg), worn (0.3 mm / 0.03 deg); several to compare",
    )
    targets = bounded_int(low=1, high=MAX_TARGETS)
    parser.add_argument(
        "--targets", type=targets, default=30, help=f"targets per run for the truth error, {targets.rule} (default 30)"
    )
    workers = bounded_int(low=1, high=MAX_WORKERS)
    parser.add_argument(
        "--workers",
        type=workers,
        default=min(os.cpu_count() or 1, MAX_WORKERS),
        help=f"local processes, {workers.rule} (default: all cores)",
    )
    add_robot_option(parser)
    parser.add_argument("--scheduler", metavar="ADDRESS", help="Dask distributed scheduler to run on")
    parser.add_argument("--force", action="store_true", help="replace existing outputs")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from brachycal.io import OutputSet  # lazy: start-up (the command's run only)

    runs = _sweep(args)  # every option and the size of the sweep checked before any work
    with OutputSet(force=args.force) as outputs:
        out = Path(args.out)
        files = [outputs.claim(out / name, make_parents=True) for name in ("runs.csv", "summary.csv", "study.png")]
        _run(args, files, runs)
    print(f"wrote {', '.join(map(str, outputs.written))}")
    return 0


def _sweep(args: argparse.Namespace) -> list[RunParams]:
    """The runs of the study (each option already range-checked by argparse)."""
    from brachycal.cli.common import load_robot  # lazy: start-up (the command's run only)
    from brachycal.studies.study import sweep  # lazy: start-up (the command's run only)

    if args.urdf is not None:  # each run loads its robot again, in its own process: by description
        from brachycal.errors import InputError  # lazy: start-up (the command's run only)

        raise InputError("study simulates a described robot: use --robot NAME|FILE, not --urdf")
    robot = load_robot(args)  # a bad description is refused here, before any run
    name = robot.rig.name if args.robot in (None, robot.rig.name) else str(Path(args.robot).resolve())
    sound = {"water": [True], "tissue": [False], "both": [True, False]}[args.sound]
    return sweep(
        args.seeds,
        args.points.tolist(),
        args.edge_mm.tolist(),
        args.annotation_px.tolist(),
        sound,
        args.outlier_rate.tolist(),
        tuple(args.methods),
        args.targets,
        tuple(args.robot_error),
        name,
    )


def _run(args: argparse.Namespace, files: list[Path], runs: list[RunParams]) -> None:
    """Run the study ``runs``; write runs, summary and plot to the staging paths ``files``."""
    from brachycal.io import write_csv  # lazy: start-up (the command's run only)
    from brachycal.reporting import save_figure, study_figure, study_table  # lazy: start-up (the command's run only)
    from brachycal.studies.study import run_study, summarise  # lazy: start-up (the command's run only)

    print(
        f"study: {len(runs)} runs (one simulated session each; {args.seeds} seeds per setting), "
        f"{'Dask at ' + args.scheduler if args.scheduler else str(args.workers) + ' local worker(s)'}"
    )
    with progress_bar(len(runs), "study", args.quiet, unit="run") as bar:
        rows = run_study(runs, workers=args.workers, scheduler=args.scheduler, progress=bar.update)
    summary = summarise(rows)
    write_csv(files[0], rows, float_format=".6f")
    write_csv(files[1], summary, float_format=".6f")
    save_figure(study_figure(summary), files[2], dpi=110)
    print(study_table(summary))
