"""Robot identification on the twin: targeting with and without it, over seeds and robot-error levels.

Run: ``.venv/bin/python benchmarks/robot_identification.py [SEEDS] [LEVEL,...]`` (default 6 seeds,
0–5, both levels; about 1.5 min per seed and level on 2 cores). A method that refuses a session
(:class:`~brachycal.errors.DegenerateDataError`) is counted, with its reason, not averaged. For
each robot-error level of the twin
(:data:`brachycal.simulation.twin.ROBOT_ERROR_LEVELS`: ``real-arm`` 0.1 mm / 0.01° per joint,
``worn`` three times that) and each method — the paper's rigid method (``kabsch``), the whole
chain (``chain``), the whole chain with the robot identified (``chain+robot``, the level as its
prior) — prints the mean and SD over seeds of:

- the end-to-end targeting error (MAE over 30 targets in the prostate cube, from the sample poses);
- the same at held-out configurations (torso turned 3°: postures the calibration never saw);
- the cross-validated image error (LOO for the first two; 8-fold over configurations for
  ``chain+robot``, every fold identifying the robot again).

Issue 19's goal: end-to-end targeting ≤ 0.15 mm mean over seeds with identification. Each level's
``chain+robot`` figures go to ``benchmarks/results.json`` (:func:`timing.record`).

``--coverage N [LEVEL]``: how often the identified fit's stated 95 % regions contain the truth over
N twin sessions (seeds 100…), the prior stated at the twin's own level: the needle and probe tips
(3D ellipsoids) and the landing error at 20 targets per session (one ellipsoid per target, from
:func:`~brachycal.calibration.chain.uncertainty.landing_covariance` with the identified robot). A
calibrated 95 % region covers 95 %; with 20 sessions, 16–20 of 20 is within binomial chance.

``--excitation [SEEDS] [LEVEL,...]``: the excitation poses (``brachycal plan excitation``) on the
twin (:func:`~brachycal.studies.excitation.evaluate_excitation`, 5-minute budget): per seed
and level, the predicted RMS landing error without and with them, the held-out and plain targeting
MAE with identification on the session alone, on the session plus the chosen poses, and on the
session plus as many plain repeats of their source poses (is it the new configurations?) and of
session samples drawn at random (is it the criterion's choice, or only the count?), the extra
minutes, and whether the criterion judged them worth recording.
"""

from __future__ import annotations

import sys
import time

import numpy as np
from timing import record

from brachycal.studies.study import run_study, sweep

LEVELS = ("real-arm", "worn")
METHODS = ("kabsch", "chain", "chain+robot")
GOAL_MM = 0.15


def main(seeds: int = 6, levels: tuple[str, ...] = LEVELS) -> None:
    start = time.perf_counter()
    runs = sweep(seeds, [4], [40.0], [1.0], methods=METHODS, targets=30, robot_errors=levels)
    rows = run_study(runs, workers=2)
    print(f"{len(runs)} twin sessions (seeds 0-{seeds - 1}) in {time.perf_counter() - start:.0f} s\n")
    print(f"{'level':<10} {'method':<12} {'targeting MAE':>16} {'held-out MAE':>16} {'CV RMSE (image)':>18} refused")
    for level in levels:
        for method in METHODS:
            every = [r for r in rows if r["robot_error"] == level and r["method"] == method]
            chosen = [r for r in every if not r["refused"]]
            refusals = sorted({str(r["refused"]) for r in every if r["refused"]})
            figures = {
                key: np.array([r[key] for r in chosen], dtype=float)
                for key in ("target_mae_mm", "target_held_out_mae_mm", "loo_rmse_mm")
            }
            cells = [f"{v.mean():.3f} ± {v.std():.3f} mm" for v in figures.values()]
            print(f"{level:<10} {method:<12} {cells[0]:>16} {cells[1]:>16} {cells[2]:>18} {len(every) - len(chosen)}")
            for reason in refusals:
                print(f"    refused: {reason}")
            if method == "chain+robot":
                for key, label in (("target_mae_mm", "targeting"), ("target_held_out_mae_mm", "held-out targeting")):
                    baseline = np.nanmean(
                        [r[key] for r in rows if r["robot_error"] == level and r["method"] == "chain"] + [np.nan]
                    )
                    value = float(figures[key].mean())
                    record(
                        f"robot identification, {level} twin: {label} MAE (mean of {seeds} seeds)",
                        value,
                        "mm",
                        goal=f"<= {GOAL_MM} mm",
                        met=value <= GOAL_MM,
                        peer="whole chain without identification",
                        peer_value=float(baseline),
                    )


def coverage(sessions: int, level: str = "real-arm") -> None:
    from brachycal.calibration import calibrate
    from brachycal.calibration.chain import RobotAccuracy
    from brachycal.calibration.chain.uncertainty import inside_ellipsoid, landing_covariance
    from brachycal.calibration.robot.identification import identify_robot
    from brachycal.model import Robot
    from brachycal.simulation.twin import TwinConfig, simulate
    from brachycal.studies.targeting import targeting_error

    robot = Robot.load()
    tips = {"needle": 0, "probe": 0}
    landed = targets = 0
    for seed in range(100, 100 + sessions):
        config = TwinConfig(seed=seed).with_robot_error(level)
        twin = simulate(robot, config)
        accuracy = RobotAccuracy(config.link_offset_sd_m, config.link_tilt_sd_rad, config.encoder_sd_rad)
        identified = identify_robot(
            twin.session, robot, calibrate(twin.session, robot, ("scaled_uv",)), "sound_speed", accuracy
        )
        fit, corrected = identified.fit, identified.robot(robot)
        for tool, name, true in (
            ("needle", "p_ER_Ntip", twin.truth.T_ER_Ntip[:3, 3]),
            ("probe", "p_EL_Ptip", twin.truth.T_EL_Ptip[:3, 3]),
        ):
            k = fit.block(name)
            tips[tool] += int(inside_ellipsoid(fit.x[k] - true, fit.covariance[k, k])[0])
        hit = targeting_error(twin, fit.calibration(), 20, software=corrected)
        C = landing_covariance(fit, corrected, twin.session.spacing_m, hit.q_read, hit.uv_px)
        landed += int(inside_ellipsoid(hit.landed_m - hit.targets_m, C).sum())
        targets += len(C)
        print(f"seed {seed}: needle {tips['needle']}, probe {tips['probe']}, landing {landed}/{targets}", flush=True)
    print(
        f"\n{level} twin, prior = its level, {sessions} sessions: 95 % regions cover the needle tip "
        f"{tips['needle']}/{sessions}, the probe tip {tips['probe']}/{sessions}, the landing error {landed}/{targets}"
    )


def excitation(seeds: int = 6, levels: tuple[str, ...] = LEVELS) -> None:
    from brachycal.model import Robot
    from brachycal.studies.excitation import evaluate_excitation

    robot = Robot.load()
    start = time.perf_counter()
    print(
        f"{'level':<9}{'seed':>5}{'touch':>6}{'samp':>5}{'min':>6}{'worth':>6}{'pred before':>12}{'pred after':>11}"
        f"{'MAE before':>11}{'MAE after':>10}{'repeats':>8}{'random':>8}{'held before':>12}{'held after':>11}"
        f"{'repeats':>8}{'random':>8}"
    )
    for level in levels:
        rows = []
        for seed in range(seeds):
            r = evaluate_excitation(robot, seed, level)
            rows.append(r)
            print(
                f"{level:<9}{seed:>5}{r['touches']:>6}{r['samples']:>5}{r['minutes']:>6.2f}{r['worth_it']!s:>6}"
                f"{r['predicted_rms_before_mm']:>12.4f}{r['predicted_rms_after_mm']:>11.4f}"
                f"{r['target_mae_before_mm']:>11.4f}{r['target_mae_after_mm']:>10.4f}{r['target_mae_repeats_mm']:>8.4f}"
                f"{r['target_mae_random_repeats_mm']:>8.4f}"
                f"{r['held_out_mae_before_mm']:>12.4f}{r['held_out_mae_after_mm']:>11.4f}"
                f"{r['held_out_mae_repeats_mm']:>8.4f}{r['held_out_mae_random_repeats_mm']:>8.4f}",
                flush=True,
            )
        mean = {k: float(np.mean([r[k] for r in rows])) for k in rows[0] if isinstance(rows[0][k], float)}
        print(
            f"{level} mean of {seeds}: predicted RMS {mean['predicted_rms_before_mm']:.4f} -> "
            f"{mean['predicted_rms_after_mm']:.4f} mm; targeting MAE {mean['target_mae_before_mm']:.4f} -> "
            f"{mean['target_mae_after_mm']:.4f} mm (repeats {mean['target_mae_repeats_mm']:.4f}, random repeats "
            f"{mean['target_mae_random_repeats_mm']:.4f}); held-out {mean['held_out_mae_before_mm']:.4f} -> "
            f"{mean['held_out_mae_after_mm']:.4f} mm (repeats {mean['held_out_mae_repeats_mm']:.4f}, random repeats "
            f"{mean['held_out_mae_random_repeats_mm']:.4f}); {mean['minutes']:.2f} extra min; "
            f"worth it in {sum(bool(r['worth_it']) for r in rows)}/{seeds}"
        )
        value = mean["held_out_mae_after_mm"]
        record(
            f"excitation poses, {level} twin: held-out targeting MAE with identification (mean of {seeds} seeds)",
            value,
            "mm",
            goal=f"<= {GOAL_MM} mm with <= 5 extra robot minutes",
            met=value <= GOAL_MM and mean["minutes"] <= 5.0,
            peer="identification on the session alone",
            peer_value=mean["held_out_mae_before_mm"],
        )
    print(f"\n{seeds * len(levels)} sessions in {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--excitation":
        excitation(
            int(sys.argv[2]) if len(sys.argv) > 2 else 6, tuple(sys.argv[3].split(",")) if len(sys.argv) > 3 else LEVELS
        )
        raise SystemExit(0)
    if len(sys.argv) > 1 and sys.argv[1] == "--coverage":
        coverage(int(sys.argv[2]), sys.argv[3] if len(sys.argv) > 3 else "real-arm")
        raise SystemExit(0)
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 6, tuple(sys.argv[2].split(",")) if len(sys.argv) > 2 else LEVELS)
