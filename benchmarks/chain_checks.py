"""Every figure docs/validation.md states about the whole-chain method, measured on the twin over seeds.

Run: ``.venv/bin/python benchmarks/chain_checks.py [RUNS] [OUTLIER_SEEDS] [--coverage-only]``
(defaults 40 and 20; ``--coverage-only``: section 1 without the bootstrap, about 15 minutes on a
busy 2-core machine). Prints:

1. **Coverage** of the stated 95 % intervals over RUNS twin sessions (seeds 100…): on the default
   twin with the robot accuracy stated at the twin's own level (the default, :data:`STATED`),
   stated 2x too small, and not stated (the session's noise alone); and on a twin whose robot is
   exactly the URDF (``kinematic_error=False``), stated 0. For the speed of sound (interval), the
   needle and probe tips (the 3D 95 % ellipsoid, χ²₃; and each coordinate, covariance and, for the
   default statement, bootstrap percentile intervals), and the landing error (the 3D ellipsoid of
   the predicted covariance at 20 targets per session: the first target, one per session, and all
   of them; "calibration part" aims with exact joint readings and leaves the readings' noise out of
   the prediction, "total" with the twin's encoder noise and in the prediction). Each rate k/n
   comes with its Wilson 95 % range, next to the range a calibrated 95 % interval gives over n
   runs; the standardised errors' SD (1 when calibrated).
2. **Outliers**: 10 % gross annotation mistakes against the clean session of the same seed
   (seeds 0…OUTLIER_SEEDS−1): the targeting-error ratio's distribution, and whether the flagged
   images are exactly the mistakes.
3. **Targeting**: the chain (model chosen by cross-validation, as ``calibrate --solve chain``)
   against the paper's rigid method (Kabsch) on the clean sessions of section 2: mean ± SD.
4. **Conditioning** figures of those fits (the ranges quoted in the thresholds' docstrings).
5. The targeting error with and without the optional joint-offset corrections on seeds 0–2.
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace

import numpy as np
from scipy.stats import binom, norm

from brachycal.calibration import Calibration, calibrate
from brachycal.calibration.chain import DEFAULT_ROBOT_ACCURACY, RobotAccuracy, fit_chain, select_model
from brachycal.calibration.chain.uncertainty import bootstrap, inside_ellipsoid, interval, landing_covariance
from brachycal.calibration.session.chain_report import WARN_LANDING_RMS_MM
from brachycal.model import Robot
from brachycal.simulation.twin import TwinConfig, simulate
from brachycal.studies.targeting import targeting_error

LEVEL = 0.95
TARGETS = 20
BOOTSTRAP = 100


def wilson(k: int, n: int) -> tuple[float, float]:
    """Wilson 95 % range of a binomial rate k/n."""
    z = norm.ppf(0.975)
    p = k / n
    centre = (p + z**2 / (2 * n)) / (1 + z**2 / n)
    half = z * np.sqrt(p * (1 - p) / n + z**2 / (4 * n**2)) / (1 + z**2 / n)
    return centre - half, centre + half


def rate(label: str, k: int, n: int, binomial: bool = True) -> str:
    if not binomial:  # outcomes correlated within a session: no binomial range applies
        return f"  {label:<46} {k:>4}/{n:<4} = {k / n:6.1%}  (correlated within each session)"
    lo, hi = wilson(k, n)
    ok_lo, ok_hi = binom.ppf(0.025, n, LEVEL) / n, binom.ppf(0.975, n, LEVEL) / n
    return (
        f"  {label:<46} {k:>4}/{n:<4} = {k / n:6.1%}  (Wilson 95 %: {lo:.1%}..{hi:.1%}; "
        f"a calibrated 95 % gives {ok_lo:.1%}..{ok_hi:.1%})"
    )


#: Stated robot accuracies of the coverage runs: the twin's own level (default), the same stated
#: 2x too small, and none (the session's noise alone).
STATED = {
    "stated = the twin's": DEFAULT_ROBOT_ACCURACY,
    "stated 2x too small": RobotAccuracy(
        DEFAULT_ROBOT_ACCURACY.translation_sd_m / 2,
        DEFAULT_ROBOT_ACCURACY.rotation_sd_rad / 2,
        DEFAULT_ROBOT_ACCURACY.encoder_sd_rad / 2,
        "half the twin's",
    ),
    "noise only (no robot term)": None,
}


def one_session(
    robot: Robot, seed: int, kinematic_error: bool, with_bootstrap: bool, accuracy: RobotAccuracy | None
) -> dict:
    twin = simulate(robot, replace(TwinConfig(seed=seed), kinematic_error=kinematic_error))
    initial = calibrate(twin.session, robot, ("scaled_uv",))
    fit = fit_chain(twin.session, robot, initial, "sound_speed", robot_accuracy=accuracy)
    truth = twin.truth
    out: dict = {}
    low, high = interval(fit, "scale")
    c = twin.config.sound_speed_m_s
    out["c_in"] = bool(low[0] * 1540 <= c <= high[0] * 1540)
    out["c_z"] = (fit.sound_speed_m_s - c) / (fit.parameter_sd()[fit.block("scale")][0] * 1540)
    for tool, name, true in (
        ("needle", "p_ER_Ntip", truth.T_ER_Ntip[:3, 3]),
        ("probe", "p_EL_Ptip", truth.T_EL_Ptip[:3, 3]),
    ):
        k = fit.block(name)
        error = fit.x[k] - true
        C = fit.covariance[k, k]
        out[f"{tool}_ellipsoid"] = bool(inside_ellipsoid(error, C, LEVEL)[0])
        out[f"{tool}_d2"] = float(error @ np.linalg.solve(C, error))
        half = norm.ppf(0.5 + LEVEL / 2) * np.sqrt(np.diag(C))
        out[f"{tool}_coords"] = int(np.sum(np.abs(error) <= half))
        out[f"{tool}_error_mm"] = error * 1e3
        out[f"{tool}_sd_mm"] = np.sqrt(np.diag(C)) * 1e3
    if with_bootstrap:
        boot = bootstrap(twin.session, robot, fit, BOOTSTRAP, seed=seed)
        for tool, true in (("needle", truth.T_ER_Ntip[:3, 3]), ("probe", truth.T_EL_Ptip[:3, 3])):
            lo, hi = boot.interval(f"p_{'ER_Ntip' if tool == 'needle' else 'EL_Ptip'}", LEVEL)
            out[f"{tool}_boot_coords"] = int(np.sum((lo <= true) & (true <= hi)))
            out[f"{tool}_boot_halfwidth_mm"] = float(np.mean(hi - lo) / 2 * 1e3)
        lo, hi = boot.interval("sound_speed_m_s", LEVEL)
        out["c_boot_in"] = bool(lo <= c <= hi)
    exact_reading = replace(twin, config=replace(twin.config, encoder_noise=False))
    for part, tw in (("calibration", exact_reading), ("total", twin)):
        hit = targeting_error(tw, fit.calibration(), TARGETS)
        C = landing_covariance(fit, robot, twin.session.spacing_m, hit.q_read, hit.uv_px, encoder_noise=part == "total")
        inside = inside_ellipsoid(hit.landed_m - hit.targets_m, C, LEVEL)
        out[f"landing_{part}_first"] = bool(inside[0])
        out[f"landing_{part}_all"] = int(inside.sum())
    return out


def coverage(robot: Robot, runs: int, with_bootstrap: bool = True) -> None:
    scenarios = [(True, label, accuracy) for label, accuracy in STATED.items()]
    exact = RobotAccuracy(0.0, 0.0, DEFAULT_ROBOT_ACCURACY.encoder_sd_rad, "exact geometry, the twin's encoder noise")
    scenarios.append((False, "geometry stated exact", exact))
    for kinematic_error, label, accuracy in scenarios:
        title = "default twin" if kinematic_error else "twin whose robot is exactly the URDF (kinematic_error=False)"
        print(f"\n1. COVERAGE OF STATED 95 % INTERVALS, {runs} sessions (seeds 100..{99 + runs}), {title}, {label}:")
        boot = with_bootstrap and kinematic_error and accuracy is DEFAULT_ROBOT_ACCURACY
        rows = [one_session(robot, 100 + i, kinematic_error, boot, accuracy) for i in range(runs)]

        def count(key: str, rows: list[dict] = rows) -> int:
            return int(sum(r[key] for r in rows))

        z = np.array([r["c_z"] for r in rows])
        print(rate("speed of sound (interval)", count("c_in"), runs) + f"; SD of (c - truth)/stated SD {z.std():.2f}")
        for tool in ("needle", "probe"):
            d2 = np.array([r[f"{tool}_d2"] for r in rows])
            print(
                rate(f"{tool} tip (3D ellipsoid)", count(f"{tool}_ellipsoid"), runs)
                + f"; mean d²/3 {d2.mean() / 3:.2f}"
            )
            print(rate(f"{tool} tip (each coordinate)", count(f"{tool}_coords"), 3 * runs))
            errors = np.array([r[f"{tool}_error_mm"] for r in rows])
            sds = np.array([r[f"{tool}_sd_mm"] for r in rows])
            print(
                f"  {'':<46} RMS error x, y, z {np.sqrt((errors**2).mean(0)).round(3).tolist()} mm; "
                f"stated SD {np.sqrt((sds**2).mean(0)).round(3).tolist()} mm"
            )
            if boot:
                half = np.array([r[f"{tool}_boot_halfwidth_mm"] for r in rows])
                print(
                    rate(f"{tool} tip, bootstrap ({BOOTSTRAP}) each coordinate", count(f"{tool}_boot_coords"), 3 * runs)
                    + f"; half-widths {half.min():.3f}..{half.max():.3f} mm"
                )
        if boot:
            print(rate(f"speed of sound, bootstrap ({BOOTSTRAP})", count("c_boot_in"), runs))
        for part in ("calibration", "total"):
            print(rate(f"landing, {part} part, first target", count(f"landing_{part}_first"), runs))
            print(
                rate(
                    f"landing, {part} part, all {TARGETS} targets", count(f"landing_{part}_all"), TARGETS * runs, False
                )
            )


def outliers_and_targeting(robot: Robot, seeds: int) -> None:
    ratios, exact_flags, chain_mae, paper_mae, gains = [], 0, [], [], []
    rcond, rotation_sd, map_max = [], [], []
    for seed in range(seeds):
        maes = []
        for dirty in (False, True):
            twin = simulate(robot, replace(TwinConfig(seed=seed), outliers=dirty))
            initial = calibrate(twin.session, robot, ("kabsch", "scaled_uv"))
            choice = select_model(twin.session, robot, initial)
            fit = fit_chain(twin.session, robot, initial, choice.model)
            hit = targeting_error(twin, fit.calibration(), 30).stats.mae_mm
            maes.append(hit)
            if dirty:
                exact_flags += bool(np.array_equal(fit.outliers, twin.outlier))
                continue
            paper = targeting_error(twin, initial.calibration("kabsch"), 30)
            chain_mae.append(hit)
            paper_mae.append(paper.stats.mae_mm)
            gains.append(paper.stats.mae_mm / hit)
            rcond.append(fit.conditioning.rcond)
            rotation_sd.append(np.degrees(max(fit.conditioning.rotation_sd_rad.values())))
            width, height = twin.session.size_px
            grid = np.array([(u, v) for v in np.arange(0, height, 60.0) for u in np.arange(0, width, 60.0)])
            uv = twin.session.uv_px
            centre = twin.session.samples_q[np.argmin(np.linalg.norm(uv - uv.mean(axis=0), axis=1))]
            C = landing_covariance(fit, robot, twin.session.spacing_m, np.repeat(centre[None], len(grid), 0), grid)
            map_max.append(np.sqrt(np.trace(C, axis1=1, axis2=2)).max() * 1e3)
        ratios.append(maes[1] / maes[0])
    r = np.array(ratios)
    print(f"\n2. OUTLIERS (10 % gross annotation mistakes, 15-40 px) vs the clean session, seeds 0..{seeds - 1}:")
    print(
        f"  targeting MAE ratio dirty/clean: median {np.median(r):.2f}, mean {r.mean():.2f} ± {r.std():.2f}, "
        f"max {r.max():.2f}; within 1.2 on {int((r <= 1.2).sum())}/{seeds}"
    )
    print(f"  per seed: {', '.join(f'{v:.2f}' for v in r)}")
    print(f"  flagged images = the mistakes exactly: {exact_flags}/{seeds}")
    chain_mae, paper_mae, gains = map(np.array, (chain_mae, paper_mae, gains))
    print(f"\n3. TARGETING MAE (30 targets), clean sessions, seeds 0..{seeds - 1}:")
    print(
        f"  chain {chain_mae.mean():.3f} ± {chain_mae.std():.3f} mm; paper's rigid method (Kabsch) "
        f"{paper_mae.mean():.3f} ± {paper_mae.std():.3f} mm; ratio paper/chain {gains.mean():.1f} ± {gains.std():.1f} "
        f"(min {gains.min():.1f}, max {gains.max():.1f})"
    )
    print("\n4. CONDITIONING of those fits:")
    print(
        f"  reciprocal condition {min(rcond):.1e}..{max(rcond):.1e}; largest rotation SD "
        f"{min(rotation_sd):.2f}..{max(rotation_sd):.2f} deg; predicted landing RMS over the image "
        f"{min(map_max):.3f}..{max(map_max):.3f} mm (warning above {WARN_LANDING_RMS_MM} mm)"
    )


def joint_offsets(robot: Robot) -> None:
    print("\n5. TARGETING MAE (mm) without / with --joint-offsets:")
    for seed in range(3):
        twin = simulate(robot, TwinConfig(seed=seed))
        initial = calibrate(twin.session, robot, ("scaled_uv",))
        plain = fit_chain(twin.session, robot, initial, "sound_speed")
        corrected = fit_chain(twin.session, robot, initial, "sound_speed", joint_offsets=True)
        a = targeting_error(twin, plain.calibration(), 30).stats.mae_mm
        b = targeting_error(
            twin,
            Calibration(corrected.T_ER_Ntip, corrected.T_EL_Ptip, corrected.image),
            30,
            software=robot.with_joint_offsets(corrected.joint_offsets_rad),
        ).stats.mae_mm
        print(f"  seed {seed}: {a:.4f} / {b:.4f}")


if __name__ == "__main__":
    import warnings

    from brachycal.errors import ConditioningWarning

    warnings.simplefilter("ignore", ConditioningWarning)  # the sequential start's grey-zone notes
    start = time.perf_counter()
    robot = Robot.load()
    coverage_only = "--coverage-only" in sys.argv  # coverage without the bootstrap, sections 2-5 skipped
    numbers = [a for a in sys.argv[1:] if not a.startswith("--")]
    coverage(robot, int(numbers[0]) if numbers else 40, with_bootstrap=not coverage_only)
    if not coverage_only:
        outliers_and_targeting(robot, int(numbers[1]) if len(numbers) > 1 else 20)
        joint_offsets(robot)
    print(f"\n({time.perf_counter() - start:.0f} s)")
