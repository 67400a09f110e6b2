"""Checks of the whole-chain method on the twin that take too long for the test suite.

Run: ``.venv/bin/python benchmarks/chain_checks.py [RUNS]``. Prints (1) how often the stated 95 %
intervals cover the truth over RUNS twin sessions (default 40, seeds 100…): the speed of sound,
and the landing-error ellipsoids of 20 targets per session; (2) the targeting error with and
without the optional joint-offset corrections on seeds 0–2.
"""

from __future__ import annotations

import sys

from brachycal.calibration import calibrate
from brachycal.calibration.chain import fit_chain
from brachycal.calibration.uncertainty import inside_ellipsoid, interval, landing_covariance
from brachycal.model import Robot
from brachycal.simulation.targeting import targeting_error
from brachycal.simulation.twin import TwinConfig, simulate


def coverage(robot: Robot, runs: int) -> None:
    c_in = first_in = all_in = total = 0
    for seed in range(100, 100 + runs):
        twin = simulate(robot, TwinConfig(seed=seed))
        fit = fit_chain(twin.session, robot, calibrate(twin.session, robot, ("scaled_uv",)), "sound_speed")
        low, high = interval(fit, 24)
        c_in += low * 1540 <= twin.config.sound_speed_m_s <= high * 1540
        hit = targeting_error(twin, fit.T_ER_Ntip, fit.T_EL_Ptip, fit.image, 20)
        C = landing_covariance(fit, robot, twin.session.spacing_m, hit.q_read, hit.uv_px)
        ok = inside_ellipsoid(hit.landed_m - hit.targets_m, C)
        first_in += ok[0]
        all_in += ok.sum()
        total += len(ok)
    print(f"interval coverage over {runs} twin sessions (stated 95%):")
    print(f"  speed of sound: {c_in}/{runs} = {c_in / runs:.1%}")
    print(
        f"  landing ellipsoid, first target: {first_in}/{runs} = {first_in / runs:.1%}; "
        f"all {total} targets: {all_in / total:.1%}"
    )


def joint_offsets(robot: Robot) -> None:
    print("targeting MAE (mm) without / with --joint-offsets:")
    for seed in range(3):
        twin = simulate(robot, TwinConfig(seed=seed))
        initial = calibrate(twin.session, robot, ("scaled_uv",))
        plain = fit_chain(twin.session, robot, initial, "sound_speed")
        corrected = fit_chain(twin.session, robot, initial, "sound_speed", joint_offsets=True)
        a = targeting_error(twin, plain.T_ER_Ntip, plain.T_EL_Ptip, plain.image, 30).stats.mae_mm
        b = targeting_error(
            twin,
            corrected.T_ER_Ntip,
            corrected.T_EL_Ptip,
            corrected.image,
            30,
            software=robot.with_joint_offsets(corrected.joint_offsets_rad),
        ).stats.mae_mm
        print(f"  seed {seed}: {a:.4f} / {b:.4f}")


if __name__ == "__main__":
    robot = Robot.load()
    coverage(robot, int(sys.argv[1]) if len(sys.argv) > 1 else 40)
    joint_offsets(robot)
