"""``brachycal study``: sweep the twin's set-up over seeds; truth error next to LOO figures."""

from __future__ import annotations

import argparse
import csv
import os
from pathlib import Path

import numpy as np

from brachycal.calibration import METHODS
from brachycal.calibration.image_to_probe import ALL_LABELS as METHOD_LABELS
from brachycal.cli.common import parse_list, progress_bar
from brachycal.errors import InputError
from brachycal.simulation.study import run_study, summarise, sweep

HELP = "sweep noise, sample count and grid size on the twin: truth error vs leave-one-out"
DESCRIPTION = """\
Answers "how many samples do we need, and how good is our calibration really": for every
combination of the swept settings and each seed, simulates a session on the digital twin,
calibrates it, and records the leave-one-out figures (what a lab sees) next to the end-to-end
targeting error against the truth (what the clinic needs).

Runs go to all local cores (--workers), or to an existing Dask distributed cluster
(--scheduler tcp://host:8786; pip install 'brachycal[cluster]'). Rows are identical to a serial
run (--workers 1) for the same seeds. Writes DIR/runs.csv (one row per run and method),
DIR/summary.csv (mean and SD over seeds) and DIR/study.png.

example:
  brachycal study --out study --points 3,4,5 --annotation-px 0.5,1,2 --seeds 5
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "study", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder")
    parser.add_argument("--seeds", type=int, default=5, help="repeats per setting (default 5)")
    parser.add_argument("--points", default="3,4,5", help="grid points per axis (default 3,4,5: 27/64/125 samples)")
    parser.add_argument("--edge-mm", default="40", help="cube edges in mm (default 40)")
    parser.add_argument("--annotation-px", default="0.5,1,2", help="annotation noise SDs in px (default 0.5,1,2)")
    parser.add_argument(
        "--sound",
        choices=("water", "tissue", "both"),
        default="water",
        help="speed of sound: water (1482 m/s, default), tissue (= scanner's 1540), or both",
    )
    parser.add_argument("--outlier-rate", default="0", help="gross annotation outlier rates (default 0)")
    parser.add_argument(
        "--methods",
        default="kabsch,scaled_uv",
        help="methods: the sequential ones and 'chain' (default kabsch,scaled_uv)",
    )
    parser.add_argument("--targets", type=int, default=30, help="targets per run for the truth error (default 30)")
    parser.add_argument("--workers", type=int, default=os.cpu_count(), help="local processes (default: all cores)")
    parser.add_argument("--scheduler", metavar="ADDRESS", help="Dask distributed scheduler to run on")
    parser.add_argument("--force", action="store_true", help="replace existing outputs")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    files = [out / "runs.csv", out / "summary.csv", out / "study.png"]
    for path in files:
        if path.exists() and not args.force:
            raise InputError("already exists; pass --force to replace it", file=path)
    methods = tuple(parse_list(args.methods, "--methods", str))
    unknown = [m for m in methods if m not in (*METHODS, "chain")]
    if unknown:
        raise InputError(f"unknown method(s) {', '.join(unknown)}; choose from {', '.join(METHODS)}, chain")
    points = parse_list(args.points, "--points", int)
    if min(points) < 2 or args.seeds < 1:
        raise InputError("--points must be at least 2 and --seeds at least 1")
    sound = {"water": [True], "tissue": [False], "both": [True, False]}[args.sound]
    runs = sweep(
        args.seeds,
        points,
        parse_list(args.edge_mm, "--edge-mm", float),
        parse_list(args.annotation_px, "--annotation-px", float),
        sound,
        parse_list(args.outlier_rate, "--outlier-rate", float),
        methods,
        args.targets,
    )
    print(
        f"study: {len(runs)} simulated sessions ({args.seeds} seeds each), "
        f"{'Dask at ' + args.scheduler if args.scheduler else str(args.workers) + ' local worker(s)'}"
    )
    with progress_bar(len(runs), "sessions", args.quiet) as bar:
        rows = run_study(runs, workers=args.workers, scheduler=args.scheduler, progress=bar.update)
    summary = summarise(rows)
    out.mkdir(parents=True, exist_ok=True)
    _write_csv(files[0], rows)
    _write_csv(files[1], summary)
    _plot(summary, files[2])
    _print(summary)
    print(f"wrote {', '.join(map(str, files))}")
    return 0


def _write_csv(path: Path, rows: list[dict]) -> None:
    from brachycal.files import atomic_open

    with atomic_open(path, force=True) as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: (f"{v:.6f}" if isinstance(v, float) else v) for k, v in row.items()})


def _print(summary: list[dict]) -> None:
    print(
        f"{'samples':>7} {'edge':>5} {'ann.px':>6} {'sound':>6} {'outl.':>5} {'method':<22} "
        f"{'LOO MAE (mm)':>14} {'target MAE (mm)':>16} {'target max':>11}"
    )
    for s in summary:
        print(
            f"{s['samples']:>7} {s['edge_mm']:>5g} {s['annotation_px']:>6g} "
            f"{'water' if s['sound_speed'] else 'tissue':>6} {s['outlier_rate']:>5g} {METHOD_LABELS[s['method']]:<22} "
            f"{s['loo_mae_mm_mean']:>7.3f} ± {s['loo_mae_mm_sd']:.3f} {s['target_mae_mm_mean']:>8.3f} ± "
            f"{s['target_mae_mm_sd']:.3f} {s['target_max_mm_mean']:>11.3f}"
        )


def _plot(summary: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    keys = sorted(
        {(s["method"], s["annotation_px"], s["edge_mm"], s["sound_speed"], s["outlier_rate"]) for s in summary}
    )
    for method, ann, edge, sound, outliers in keys:
        rows = sorted(
            (
                s
                for s in summary
                if (s["method"], s["annotation_px"], s["edge_mm"], s["sound_speed"], s["outlier_rate"])
                == (method, ann, edge, sound, outliers)
            ),
            key=lambda s: s["samples"],
        )
        n = np.array([s["samples"] for s in rows])
        label = f"{METHOD_LABELS[method]}, {ann:g} px, {edge:g} mm" + ("" if sound else ", tissue")
        for ax, figure in zip(axes, ("loo_mae_mm", "target_mae_mm"), strict=True):
            ax.errorbar(
                n,
                [s[f"{figure}_mean"] for s in rows],
                yerr=[s[f"{figure}_sd"] for s in rows],
                marker="o",
                capsize=3,
                label=label,
            )
    axes[0].set_title("leave-one-out MAE (what a lab sees)")
    axes[1].set_title("end-to-end targeting MAE (truth)")
    for ax in axes:
        ax.set_xlabel("samples")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("mm")
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
