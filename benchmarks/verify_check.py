"""The pre-procedure check (``brachycal plan check`` + ``brachycal verify``) measured on the twin.

Run: ``.venv/bin/python benchmarks/verify_check.py [SEEDS] [CHECKS] [LEVEL,...] [--poses N] [--touches WHICH]
[--first-seed K] [--average-null] [--updates]`` (default: the check of ``plan check``, 8 samples + the probe's
touch; ``--touches`` both, probe or none: which tools touch ``rtip1`` once, ``plan check --touches``;
20 seeds from :data:`FIRST_SEED`, 10 checks per seed for the unchanged set-up and 5 per seed for each
change; the ``well-built`` and ``real-arm`` robots; each check is given the calibration session, for
each pose's own null SD, unless ``--average-null``; about 15 minutes on a busy 2-core machine).
With ``--updates``, each failed check updates the result where it may (``verify --update``) and a
second table gives, per change, how many failed checks were updated and the targeting error (RMS
over the check poses of the noise-free residuals, mm) before the change, ignoring it, and with the
updated result (means over the updated checks).

Per robot-error level (:data:`brachycal.simulation.twin.ROBOT_ERROR_LEVELS`) and seed, the twin's
session is calibrated with the whole chain (:class:`~brachycal.studies.check_twin.CalibratedTwin`)
and the check's poses are chosen from the same grid (``plan check``'s criterion). Then each
change of :data:`~brachycal.studies.check_twin.CHANGES` is applied and a check session is
recorded with fresh noise (the checks of one seed share its calibration: the rates are over
seeds × checks, and the binomial 95 % interval printed assumes independent checks, which the
shared calibrations make a little optimistic). Printed per change: how often the verdict is
RECALIBRATE (the false-alarm rate for "unchanged", else the detection rate) with its Wilson 95 %
interval, how often the named part is the one that moved, and the true targeting change (RMS over
the check poses of the change of the noise-free check residual: what ignoring it would cost).

Settings other than the defaults the check was designed on (:class:`~brachycal.studies.check_twin.TwinSettings`):
``--annotation-px PX``, ``--robot-mm MM --robot-deg DEG`` (each joint origin's error as a 3-D norm),
``--touch-turn-deg DEG`` (each check touch re-done by hand turned by up to this), ``--beam-mm MM``,
``--cad-close``, ``--every-trial`` (the check touches as the calibration does: every trial, both tips),
``--not-stated`` (the calibration states the default accuracy, not the arm's). With ``--grid``, only
unchanged set-ups are checked, over :data:`GRID` (each row: robot level and settings), and one table
of false alarms per setting is printed: ``verify_check.py --grid SEEDS CHECKS [--first-seed K]`` (from
:data:`GRID_FIRST_SEED` unless given).

Goals (issue 22): false alarms ≤ 5 % on unchanged set-ups; detection ≥ 95 % for changes that move
targeting by more than 0.5 mm; robot time per check < 2 min at 10 s per sample. Both levels'
figures go to ``benchmarks/results.json`` (:func:`timing.record`) when the defaults are run.
"""

from __future__ import annotations

import sys
import tempfile
import time
from collections import defaultdict

import numpy as np

from brachycal.planning.check_poses import DEFAULT_CHECK_POSES as DEFAULT_POSES  # the figures recorded are for it
from brachycal.planning.check_poses import DEFAULT_TOUCHES, TOUCH_CHOICES

#: The seeds docs/validation.md's table is measured on: 80 and up, seeds no choice of the check was made on.
#: Seeds 0–19 were used to choose the touches' null SD, 20–39 to find the corner poses' excess (each
#: pose's own null SD) and to try the per-part tests, 40–79 to measure the check before the per-part
#: tests (the 0.5 mm remount found in 93 and 95 of 100 on the real arm): figures on them would
#: flatter the check. The settings table (``--grid``) is measured on seeds 110 and up: 0–15 were
#: used to reproduce the false alarms on other settings, 100–109 found the every-trial check's
#: false alarms that the robot-accuracy null first had (its noise share) and checked the fix.
FIRST_SEED = 80
#: The first seed of docs/validation.md's settings table (``--grid``).
GRID_FIRST_SEED = 110
#: The part each change should be named as (probe mount: a remount moves the probe with its image).
EXPECTED_PART = {
    "probe remounted 0.5 mm / 0.5 deg": "probe mount",
    "probe remounted 1 mm / 1 deg": "probe mount",
    "needle tip bent 0.3 mm": "needle tip",
    "another needle (tip 3 mm along it)": "needle tip",
    "speed of sound 1482 -> 1510 m/s": "image scale",
    "probe-arm joint 2 zero drift 0.03 deg": "robot",
    "probe re-seated (image 0.5 mm / 0.5 deg)": "image transform",
}


def _grid() -> dict[str, tuple[str, object]]:
    """The settings the false-alarm table is measured over: robot level and twin settings."""
    from brachycal.studies.check_twin import TwinSettings

    r = np.radians
    issue = {"annotation_px": 1.2, "robot_translation_m": 1e-4, "robot_rotation_rad": r(0.01)}
    return {
        "defaults (well-built)": ("well-built", TwinSettings()),
        "defaults (real-arm)": ("real-arm", TwinSettings()),
        "0.5 px": ("real-arm", TwinSettings(annotation_px=0.5)),
        "2 px": ("real-arm", TwinSettings(annotation_px=2.0)),
        "1.2 px, robot 0.1 mm / 0.01 deg (3-D), touches turned <= 3 deg, CAD-close": (
            "real-arm",
            TwinSettings(**issue, touch_turn_rad=r(3.0), cad_close=True),
        ),
        "the same, tip in the image plane (beam 0)": (
            "real-arm",
            TwinSettings(**issue, touch_turn_rad=r(3.0), cad_close=True, beam_thickness_m=0.0),
        ),
        "the same, every touch trial on both tips (needle and probe)": (
            "real-arm",
            TwinSettings(**issue, touch_turn_rad=r(3.0), cad_close=True, every_trial=True),
        ),
        "real-arm, touches turned <= 10 deg": ("real-arm", TwinSettings(touch_turn_rad=r(10.0))),
        "real-arm, accuracy not stated (default stated)": ("real-arm", TwinSettings(stated=False)),
        "worn (0.3 mm / 0.03 deg per axis)": ("worn", TwinSettings()),
    }


def grid(seeds: int, checks: int, first: int) -> None:
    """False alarms on unchanged set-ups over :func:`_grid`'s settings: one table."""
    import warnings

    from brachycal.errors import BrachycalError
    from brachycal.model import Robot
    from brachycal.studies.check_twin import CHANGES, CalibratedTwin

    robot = Robot.load(None)
    rows = []
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as folder:
        for name, (level, settings) in _grid().items():
            alarms, n, refused, touches = 0, 0, 0, "both" if settings.every_trial else DEFAULT_TOUCHES
            for seed in range(first, first + seeds):
                try:
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")  # the sequential start's conditioning warnings
                        twin = CalibratedTwin(
                            seed, robot, folder, robot_error=level, touches=touches, settings=settings
                        )
                except BrachycalError:  # the calibration refuses (e.g. the worn arm): no check to make
                    refused += 1
                    continue
                for k in range(checks):
                    alarms += twin.trial(CHANGES["unchanged"], k).verdict == "RECALIBRATE"
                    n += 1
            lo, hi = wilson(alarms, n) if n else (0.0, 1.0)
            rate = f"{alarms}/{n} = {100 * alarms / max(n, 1):.1f} % ({100 * lo:.1f}–{100 * hi:.1f} %)"
            rows.append(f"| {name} | {level} | {rate} | {refused} |")
            print(f"  {name} done ({time.perf_counter() - start:.0f} s)", flush=True)
    print(f"\nseeds {first}-{first + seeds - 1}, {checks} checks each of the unchanged set-up")
    print("| settings | robot level | false alarms (95 % interval) | calibrations refused |")
    print("|---|---|---|---|")
    print("\n".join(rows))


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson 95 % interval of a binomial proportion ``k / n``."""
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def main(argv: list[str]) -> None:
    from timing import record

    from brachycal.model import Robot
    from brachycal.studies.check_twin import CHANGES, CalibratedTwin, TwinSettings

    options = {"--poses": str(DEFAULT_POSES), "--touches": DEFAULT_TOUCHES, "--first-seed": str(FIRST_SEED)}
    numbers = {"--annotation-px": None, "--robot-mm": None, "--robot-deg": None, "--touch-turn-deg": None}
    numbers["--beam-mm"] = None
    flags = {"--cad-close": False, "--every-trial": False, "--not-stated": False, "--grid": False}
    words: list[str] = []
    pose_nulls, updates = True, False
    args = iter(argv)
    for arg in args:
        if arg == "--average-null":
            pose_nulls = False
        elif arg == "--updates":
            updates = True
        elif arg in flags:
            flags[arg] = True
        elif arg in numbers:
            numbers[arg] = float(next(args, "nan"))
        elif arg in options:
            options[arg] = next(args, "")
        elif arg.startswith("--"):
            raise SystemExit(f"unknown option {arg}")
        else:
            words.append(arg)
    if flags["--grid"] and "--first-seed" not in argv:
        options["--first-seed"] = str(GRID_FIRST_SEED)
    poses, touches, first = int(options["--poses"]), options["--touches"], int(options["--first-seed"])
    if touches not in TOUCH_CHOICES:
        raise SystemExit(f"--touches must be one of {', '.join(TOUCH_CHOICES)}")
    touched = len(TOUCH_CHOICES[touches])
    seeds = int(words[0]) if words else 20
    checks = int(words[1]) if len(words) > 1 else 10
    if flags["--grid"]:
        grid(seeds, checks, first)
        return
    levels = words[2].split(",") if len(words) > 2 else ["well-built", "real-arm"]
    mm, deg, turn, beam = (numbers[k] for k in ("--robot-mm", "--robot-deg", "--touch-turn-deg", "--beam-mm"))
    settings = TwinSettings(
        annotation_px=numbers["--annotation-px"],
        robot_translation_m=None if mm is None else mm * 1e-3,
        robot_rotation_rad=None if deg is None else float(np.radians(deg)),
        touch_turn_rad=0.0 if turn is None else float(np.radians(turn)),
        beam_thickness_m=None if beam is None else beam * 1e-3,
        cad_close=flags["--cad-close"],
        every_trial=flags["--every-trial"],
        stated=not flags["--not-stated"],
    )
    robot = Robot.load(None)
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as folder:
        for level in levels:
            verdicts: dict[str, list[bool]] = defaultdict(list)
            named: dict[str, list[bool]] = defaultdict(list)
            change_mm: dict[str, list[float]] = defaultdict(list)
            updated: dict[str, list[tuple[float, float, float | None]]] = defaultdict(list)
            minutes = []
            for seed in range(first, first + seeds):
                twin = CalibratedTwin(
                    seed,
                    robot,
                    folder,
                    robot_error=level,
                    count=poses,
                    touches=touches,
                    pose_nulls=pose_nulls,
                    settings=settings,
                )
                minutes.append(twin.check_plan.robot_minutes)
                for name, change in CHANGES.items():
                    n = checks if name == "unchanged" else max(1, checks // 2)
                    for k in range(n):
                        outcome = twin.trial(change, k, update=updates)
                        verdicts[name].append(outcome.verdict == "RECALIBRATE")
                        if updates and outcome.verdict == "RECALIBRATE":
                            o = outcome
                            figures = (o.targeting_before_mm, o.targeting_ignored_mm, o.targeting_updated_mm)
                            updated[name].append(figures)
                        if name != "unchanged":
                            named[name].append(outcome.part == EXPECTED_PART[name])
                            change_mm[name].append(outcome.targeting_change_mm)
                print(f"  {level} seed {seed} done ({time.perf_counter() - start:.0f} s)", flush=True)
            setup = f"{poses} samples" + (f" + {touched} touch{'es' if touched > 1 else ''}" if touched else "")
            setup += f" ({touches})" if touched == 1 else ""
            null = "each pose's own null SD" if pose_nulls else "the average null SD"
            print(
                f"\n{level} robot ({settings.label()}), {setup}, seeds {first}-{first + seeds - 1}, {null}: "
                f"robot time {np.mean(minutes):.2f} min per check"
            )
            print("| change | targeting change (mm, mean) | RECALIBRATE | 95 % interval | part named right |")
            print("|---|---|---|---|---|")
            for name in CHANGES:
                v = verdicts[name]
                k, n = int(np.sum(v)), len(v)
                lo, hi = wilson(k, n)
                moved = f"{np.mean(change_mm[name]):.2f}" if name != "unchanged" else "0"
                right = f"{int(np.sum(named[name]))}/{k}" if name != "unchanged" else "-"
                right = right if name == "unchanged" else f"{int(np.sum(np.array(named[name]) & np.array(v)))}/{k}"
                print(
                    f"| {name} | {moved} | {k}/{n} ({100 * k / n:.1f} %) | {100 * lo:.1f}–{100 * hi:.1f} % | {right} |"
                )
            if updates:
                print("\n| change (checks that failed) | updated | targeting before the change | ignored | updated |")
                print("|---|---|---|---|---|")
                for name in CHANGES:
                    rows = updated[name]
                    made = [r for r in rows if r[2] is not None]
                    if not rows:
                        continue
                    means = [f"{np.mean([r[k] for r in made]):.2f} mm" if made else "–" for k in range(3)]
                    print(f"| {name} | {len(made)}/{len(rows)} | {' | '.join(means)} |")
            # the validation page's run: only the default check's figures are recorded
            default = touches == DEFAULT_TOUCHES and poses == DEFAULT_POSES and pose_nulls and first == FIRST_SEED
            default = default and settings == TwinSettings()
            if default and seeds >= 20:
                v = verdicts["unchanged"]
                rate = float(np.mean(v))
                record(
                    f"verify: false-alarm rate, unchanged {level} twin ({setup})",
                    100 * rate,
                    "%",
                    goal="<= 5 %",
                    met=rate <= 0.05,
                )
                big = [n for n in EXPECTED_PART if np.mean(change_mm[n]) > 0.5]
                worst = min(float(np.mean(verdicts[n])) for n in big)
                record(
                    f"verify: lowest detection rate, {level} twin, changes moving targeting > 0.5 mm",
                    100 * worst,
                    "%",
                    goal=">= 95 %",
                    met=worst >= 0.95,
                )
                record(
                    "verify: robot time per check (10 s per sample, 30 s per touch)",
                    float(np.mean(minutes)),
                    "min",
                    goal="< 2 min",
                    met=float(np.mean(minutes)) < 2.0,
                )


if __name__ == "__main__":
    sys.path.insert(0, str(__import__("pathlib").Path(__file__).parent))
    main(sys.argv[1:])
