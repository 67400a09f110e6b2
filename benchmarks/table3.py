"""Table III on the twin: the tracker route against the fusion methods, over seeds, with the spread.

Run: ``.venv/bin/python benchmarks/table3.py [--seeds N] [--targets M] [--no-chain]`` (defaults:
seeds 0–9, 50 targets per seed; about 15 s per seed on one core). For each seed the twin session
is simulated, calibrated by the fusion methods, and the same simulated robot is calibrated by the
tracker route (:mod:`brachycal.simulation.nwire_twin`, its defaults: NDI Polaris Spectra
0.25 mm RMS per marker, 20 frames averaged per static capture, wire beam thickness, phantom
tolerance, landmark registration). Every method is judged by the whole-system targeting error
(MAE over the targets, mm); the table gives the mean ± SD over seeds, the smallest and largest
seed, and the per-seed MAEs. A second table changes one assumption of the tracker route at a
time, to show what each one is worth.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from brachycal.calibration import calibrate, fit_chain, select_model
from brachycal.model import Robot
from brachycal.simulation.nwire_twin import NWireSimConfig, tracker_route
from brachycal.simulation.targeting import targeting_error
from brachycal.simulation.twin import Twin, TwinConfig, simulate

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


def _mae(twin: Twin, T_ER_Ntip: np.ndarray, T_EL_probe: np.ndarray, image, targets: int) -> float:
    return targeting_error(twin, T_ER_Ntip, T_EL_probe, image, targets).stats.mae_mm


def run(seeds: int, targets: int, chain: bool) -> tuple[dict[str, list[float]], dict[str, list[float]], list[str]]:
    """Per-seed MAEs (mm) of the methods and of the tracker-route variants, and the chain's models."""
    robot = Robot.load()
    methods: dict[str, list[float]] = {"N-wire + optical tracker (hand-eye)": [], "Kabsch (paper)": []}
    methods["Scaled u/v"] = []
    if chain:
        methods["Chain (model by cross-validation)"] = []
    variants: dict[str, list[float]] = {label: [] for label in VARIANTS}
    chosen = []
    for seed in range(seeds):
        start = time.perf_counter()
        twin = simulate(robot, TwinConfig(seed=seed))
        result = calibrate(twin.session, robot, ("kabsch", "scaled_uv"))
        needle = result.T_ER_Ntip
        sim = NWireSimConfig(seed=seed)
        route = tracker_route(twin, sim)
        methods["N-wire + optical tracker (hand-eye)"].append(
            _mae(twin, needle, route.T_EL_marker, route.image, targets)
        )
        methods["Kabsch (paper)"].append(_mae(twin, needle, result.T_EL_Ptip, result.image["kabsch"], targets))
        methods["Scaled u/v"].append(_mae(twin, needle, result.T_EL_Ptip, result.image["scaled_uv"], targets))
        if chain:
            model = select_model(twin.session, robot, result).model
            fit = fit_chain(twin.session, robot, result, model)
            chosen.append(model)
            methods["Chain (model by cross-validation)"].append(
                _mae(twin, fit.T_ER_Ntip, fit.T_EL_Ptip, fit.image, targets)
            )
        for label, change in VARIANTS.items():
            other = tracker_route(twin, change(sim))
            variants[label].append(_mae(twin, needle, other.T_EL_marker, other.image, targets))
        print(f"  seed {seed} done in {time.perf_counter() - start:.1f} s", flush=True)
    return methods, variants, chosen


def _row(label: str, maes: list[float], width: int) -> str:
    a = np.asarray(maes)
    spread = f"{a.std(ddof=1):.3f}" if len(a) > 1 else "  -  "
    return f"  {label:<{width}} {a.mean():.3f} ± {spread}   {a.min():.3f}–{a.max():.3f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10, help="seeds 0..N-1 (default 10)")
    parser.add_argument("--targets", type=int, default=50, help="targets per seed (default 50)")
    parser.add_argument("--no-chain", action="store_true", help="leave out the whole-chain method (the slowest)")
    args = parser.parse_args()
    methods, variants, chosen = run(args.seeds, args.targets, not args.no_chain)
    n = args.seeds
    width = max(map(len, [*methods, *variants]))
    print(f"\nTABLE III on the twin: whole-system targeting error, MAE over {args.targets} targets, seeds 0–{n - 1}")
    print(f"  {'method':<{width}} mean ± SD over seeds (mm)   min–max")
    for label, maes in methods.items():
        print(_row(label, maes, width))
    if chosen:
        print(f"  (chain's image model per seed: {', '.join(chosen)})")
    print("\n  per seed (mm):")
    for label, maes in methods.items():
        print(f"  {label:<{width}} " + " ".join(f"{m:.3f}" for m in maes))
    tracker = np.asarray(methods["N-wire + optical tracker (hand-eye)"])
    for label, maes in methods.items():
        if label.startswith("N-wire"):
            continue
        diff = tracker - np.asarray(maes)
        print(
            f"  tracker route − {label}: {diff.mean():+.3f} ± {diff.std(ddof=1) if n > 1 else 0:.3f} mm, "
            f"tracker route better on {int((diff < 0).sum())} of {n} seeds"
        )
    print("\nThe tracker route with one assumption changed (MAE mm, mean ± SD over seeds, min–max):")
    print(_row("defaults (as above)", list(tracker), width))
    for label, maes in variants.items():
        print(_row(label, maes, width))


if __name__ == "__main__":
    main()
