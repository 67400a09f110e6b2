"""Table III on the twin, complete: fusion, whole chain and three phantom routes, over seeds, with the spread.

Run: ``.venv/bin/python benchmarks/table3.py [--seeds N] [--targets M] [--no-chain] [--no-variants]``
(defaults: seeds 0–9, 50 targets per seed; about 5 s per seed for the table on one core, ~10 s more
with the variants). For each seed the twin session is simulated and calibrated by the paper's
fusion methods (ICP, Kabsch, landmark/Horn) and brachycal's whole chain; the same simulated robot
is calibrated by the tracker route with three phantoms: N-wire
(:mod:`brachycal.studies.nwire_twin`), multi-wedge and arbitrary wire
(:mod:`brachycal.studies.phantom_twin`), all with the N-wire twin's tracker practice (NDI
Polaris Spectra 0.25 mm RMS per marker, 20 frames averaged per static capture, phantom print
tolerance, landmark registration, beam thickness) and one shared hand–eye calibration. Every
method is judged by the whole-system targeting error (MAE over the targets, mm); the table gives
the mean ± SD over seeds, the smallest and largest seed, the per-seed MAEs and the paper's figure.
A second table changes one assumption of the N-wire route at a time, to show what each is worth.
``brachycal demo --table3`` prints the first table (brachycal.studies.demo.table3).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from brachycal.calibration import Calibration
from brachycal.model import Robot
from brachycal.simulation.twin import TwinConfig, simulate
from brachycal.studies.demo import Table3, table3_text, table3_twin
from brachycal.studies.nwire_twin import NWireSimConfig, tracker_route
from brachycal.studies.targeting import targeting_error

#: The tracker route under other assumptions: label → change from the defaults.
VARIANTS: dict[str, Callable[[NWireSimConfig], NWireSimConfig]] = {
    "one tracker frame per capture (no averaging)": lambda s: replace(s, tracker_frames=1),
    "all 0.25 mm as jitter (averaging removes it)": lambda s: replace(s, tracker_jitter_m=s.tracker_accuracy_m),
    "error field correlation length 0.05 m": lambda s: replace(s, tracker_field_length_m=0.05),
    "error field correlation length 0.3 m": lambda s: replace(s, tracker_field_length_m=0.3),
    "NDI Polaris Vega (0.12 mm RMS)": lambda s: replace(s, tracker_accuracy_m=0.12e-3, tracker_jitter_m=0.08e-3),
    "N-wire as a sweep, 10 ms latency, one frame": lambda s: replace(s, latency=True),
    "no wire beam thickness": lambda s: replace(s, wire_beam_thickness=False),
    "no phantom tolerance": lambda s: replace(s, phantom_tolerance=False),
    "tracker error off": lambda s: replace(s, tracker_noise=False),
    "every N-wire/tracker error off (robot's only)": lambda s: s.without_noise(),
    "as coded before: 0.25 mm per axis, one frame": lambda s: replace(
        s.without_noise(),
        tracker_noise=True,
        segmentation_noise=True,
        landmark_noise=True,
        tracker_accuracy_m=0.25e-3 * np.sqrt(3.0),
        tracker_jitter_m=0.25e-3 * np.sqrt(3.0),
        tracker_frames=1,
    ),
}


def run(
    seeds: int, targets: int, chain: bool, variants: bool
) -> tuple[dict[str, list[float]], dict[str, list[float]], list[str]]:
    """Per-seed MAEs (mm) of Table III's rows and of the N-wire route's variants, and the chain's models."""
    robot = Robot.load()
    methods: dict[str, list[float]] = {}
    changed: dict[str, list[float]] = {label: [] for label in VARIANTS} if variants else {}
    chosen = []
    for seed in range(seeds):
        start = time.perf_counter()
        twin = simulate(robot, TwinConfig(seed=seed))
        row, model, result = table3_twin(robot, twin, targets, chain)
        for label, value in row.items():
            methods.setdefault(label, []).append(value)
        if model is not None:
            chosen.append(model)
        sim = NWireSimConfig(seed=seed)
        for label, change in VARIANTS.items() if variants else ():
            other = tracker_route(twin, change(sim))
            changed[label].append(
                targeting_error(
                    twin, Calibration(result.T_ER_Ntip, other.T_EL_marker, other.image), targets
                ).stats.mae_mm
            )
        print(f"  seed {seed} done in {time.perf_counter() - start:.1f} s", flush=True)
    return methods, changed, chosen


def _row(label: str, maes: list[float], width: int) -> str:
    a = np.asarray(maes)
    spread = f"{a.std(ddof=1):.3f}" if len(a) > 1 else "  -  "
    return f"  {label:<{width}} {a.mean():.3f} ± {spread}   {a.min():.3f}–{a.max():.3f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10, help="seeds 0..N-1 (default 10)")
    parser.add_argument("--targets", type=int, default=50, help="targets per seed (default 50)")
    parser.add_argument("--no-chain", action="store_true", help="leave out the whole-chain method (the slowest)")
    parser.add_argument("--no-variants", action="store_true", help="leave out the N-wire route's variants")
    args = parser.parse_args()
    methods, variants, chosen = run(args.seeds, args.targets, not args.no_chain, not args.no_variants)
    n = args.seeds
    print()
    table = Table3.from_rows(range(n), args.targets, methods, chosen)
    print(table3_text(table))
    methods = table.maes_mm
    width = max(map(len, [*methods, *variants]))
    print("\n  per seed (mm):")
    for label, maes in methods.items():
        print(f"  {label:<{width}} " + " ".join(f"{m:.3f}" for m in maes))
    tracker = np.asarray(methods["N-wire + tracker"])
    for label, maes in methods.items():
        if label.startswith("N-wire"):
            continue
        diff = tracker - np.asarray(maes)
        print(
            f"  N-wire route − {label}: {diff.mean():+.3f} ± {diff.std(ddof=1) if n > 1 else 0:.3f} mm, "
            f"N-wire route better on {int((diff < 0).sum())} of {n} seeds"
        )
    if variants:
        print("\nThe N-wire route with one assumption changed (MAE mm, mean ± SD over seeds, min–max):")
        print(_row("defaults (as above)", list(tracker), width))
        for label, maes in variants.items():
            print(_row(label, maes, width))


if __name__ == "__main__":
    main()
