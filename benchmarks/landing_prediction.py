"""How honest the whole chain's predicted landing error is, on twins other than the default.

Run: ``.venv/bin/python benchmarks/landing_prediction.py [SEEDS] [FIRST_SEED]`` (defaults 12 and 0;
about 20 minutes on a busy 2-core machine).

For each setting of :data:`SETTINGS` (robot-error level, twin settings other than the defaults,
method) and each seed, the twin's session is calibrated with the whole chain (the image model chosen
by cross-validation, as ``calibrate --solve chain``; ``chain+robot``: the robot identified too), the
robot's accuracy stated at the twin's own per-axis level (:class:`~brachycal.calibration.chain.RobotAccuracy`:
each joint origin's translation and rotation SD per axis and its zero offset's SD, the joint
readings' SD; the last two settings state the geometry's √3 too large, as a lab would that took a
3-D figure for a per-axis one), and the needle is aimed at 20 targets
(:func:`~brachycal.studies.targeting.landing_check`). Printed per setting: the ratio of the actual
RMS landing error to the predicted one over the sessions (median, quartiles, range; honest: a
median in 0.67–1.5; last column: the median with the robot's error taken from the stated accuracy
alone, blind to what the residuals show of it; an identified robot's is its own posterior), and how
often the stated 95 % ellipsoid holds the error: at the first target of each session (independent
sessions: a calibrated 95 % gives the binomial range printed) and at all targets (correlated within a
session: one draw of the robot's error).
"""

from __future__ import annotations

import sys
import time
import warnings
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.stats import binom

from brachycal.calibration import calibrate
from brachycal.calibration.chain import RobotAccuracy, fit_chain, select_model
from brachycal.calibration.robot.identification import choose_and_identify
from brachycal.errors import BrachycalError, ConditioningWarning
from brachycal.model import Robot
from brachycal.planning import PlanSpec
from brachycal.simulation.twin import TwinConfig, simulate
from brachycal.studies.targeting import LandingCheck, landing_check

LEVEL = 0.95
TARGETS = 20


@dataclass(frozen=True)
class Setting:
    """A twin (robot-error level, settings changed from :class:`TwinConfig`'s) and a method."""

    level: str
    changes: dict[str, Any]
    method: str = "chain"
    points_per_axis: int = 4
    overstated: float = 1.0


R = float(np.radians(0.01))
#: The settings measured: the default twin, then non-default noise, sample counts and robot accuracy.
SETTINGS = {
    "default twin (well-built)": Setting("well-built", {}),
    "real-arm": Setting("real-arm", {}),
    "real-arm, 0.5 px": Setting("real-arm", {"annotation_sd_px": 0.5}),
    "real-arm, 2 px": Setting("real-arm", {"annotation_sd_px": 2.0}),
    "real-arm, 27 samples, 2 trials": Setting("real-arm", {"trials": 2}, points_per_axis=3),
    "real-arm, encoder 1e-4 rad": Setting("real-arm", {"encoder_sd_rad": 1e-4}),
    "real-arm, jog 0.2 mm, beam 2 mm": Setting("real-arm", {"jog_sd_m": 2e-4, "beam_thickness_m": 2e-3}),
    "1.2 px, robot 0.1 mm / 0.01 deg (3-D), CAD-close": Setting(
        "real-arm",
        {
            "annotation_sd_px": 1.2,
            "link_offset_sd_m": 1e-4 / np.sqrt(3),
            "link_tilt_sd_rad": R / np.sqrt(3),
            "joint_offset_sd_rad": R / np.sqrt(3),
            "tool_offset_sd_m": 2e-4,
            "tool_tilt_sd_rad": float(np.radians(0.1)),
        },
    ),
    "real-arm, robot identified": Setting("real-arm", {}, method="chain+robot"),
    "worn, robot identified": Setting("worn", {}, method="chain+robot"),
    "real-arm, its geometry's accuracy stated 1.73x too large": Setting("real-arm", {}, overstated=float(np.sqrt(3))),
    "0.3 mm / 0.03 deg (3-D), stated 0.3 mm / 0.03 deg per axis": Setting(
        "worn",
        {
            "link_offset_sd_m": 3e-4 / np.sqrt(3),
            "link_tilt_sd_rad": 3 * R / np.sqrt(3),
            "joint_offset_sd_rad": 3 * R / np.sqrt(3),
        },
        overstated=float(np.sqrt(3)),
    ),
}


def session_check(robot: Robot, setting: Setting, seed: int) -> tuple[LandingCheck, float] | None:
    """One session of ``setting``: its landing check and the ratio the stated accuracy alone (the
    prior, blind to what the residuals show of the robot) gives, or None where the calibration
    refuses it."""
    config = replace(TwinConfig(seed=seed).with_robot_error(setting.level), **setting.changes)
    if setting.points_per_axis != 4:
        config = replace(config, spec=PlanSpec.for_robot(robot, points_per_axis=setting.points_per_axis))
    twin = simulate(robot, config)
    stated = RobotAccuracy(
        config.link_offset_sd_m * setting.overstated,
        config.link_tilt_sd_rad * setting.overstated,
        config.encoder_sd_rad,
        "the twin's",
    )
    try:
        initial = calibrate(twin.session, robot, ("kabsch", "scaled_uv"))
        if setting.method == "chain+robot":
            _, identified = choose_and_identify(twin.session, robot, initial, stated)
            check = landing_check(twin, identified.fit, TARGETS, software=identified.robot(robot))
            return check, check.ratio  # its robot term is a posterior already
        choice = select_model(twin.session, robot, initial)
        fit = fit_chain(twin.session, robot, initial, choice.model, robot_accuracy=stated)
    except BrachycalError:  # refused (a worn arm's rotations undetermined without identification)
        return None
    prior = landing_check(twin, replace(fit, robot_mean=None, robot_posterior=None), TARGETS)
    return landing_check(twin, fit, TARGETS), prior.ratio


def main(seeds: int, first: int) -> None:
    warnings.simplefilter("ignore", ConditioningWarning)  # the sequential start's grey-zone notes
    robot = Robot.load()
    start = time.perf_counter()
    ok_lo, ok_hi = (int(binom.ppf(q, seeds, LEVEL)) for q in (0.025, 0.975))
    print(f"seeds {first}..{first + seeds - 1}, {TARGETS} targets each; actual / predicted RMS landing error")
    print(
        "| setting | sessions | median ratio | quartiles | range | first target in 95 % | all targets in 95 % "
        "| median ratio, stated accuracy alone |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for name, setting in SETTINGS.items():
        pairs = [c for c in (session_check(robot, setting, first + k) for k in range(seeds)) if c is not None]
        checks = [c for c, _ in pairs]
        ratios = np.array([c.ratio for c in checks])
        prior = float(np.median([r for _, r in pairs]))
        q1, median, q3 = np.percentile(ratios, [25, 50, 75])
        first_in = sum(bool(c.inside[0]) for c in checks)
        all_in = sum(int(c.inside.sum()) for c in checks)
        print(
            f"| {name} | {len(checks)} | {median:.2f} | {q1:.2f}–{q3:.2f} | {ratios.min():.2f}–{ratios.max():.2f} "
            f"| {first_in}/{len(checks)} | {all_in}/{TARGETS * len(checks)} ({all_in / (TARGETS * len(checks)):.0%}) "
            f"| {prior:.2f} |",
            flush=True,
        )
    seconds = time.perf_counter() - start
    print(f"(a calibrated 95 % holds the first target on {ok_lo}..{ok_hi} of {seeds}; {seconds:.0f} s)")


if __name__ == "__main__":
    numbers = [int(a) for a in sys.argv[1:3]]
    main(numbers[0] if numbers else 12, numbers[1] if len(numbers) > 1 else 0)
