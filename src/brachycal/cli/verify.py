"""``brachycal verify``: is the stored calibration still good? A check of a few minutes before each procedure."""

from __future__ import annotations

import argparse
from pathlib import Path

from brachycal.cli.common import add_method_option, add_robot_option, load_robot
from brachycal.errors import InputError
from brachycal.validate import finite_float

HELP = "check a stored calibration on a few new samples: PASS, or RECALIBRATE naming the part that moved"
DESCRIPTION = """\
Predicts each sample of CHECK_SESSION (a session folder with session.toml and samples.csv: the 6
poses of 'brachycal plan --verify', the needle tip annotated; optionally touches.csv with single
touches of the needle and/or the probe on a reference tip) from RESULT, and tests the residuals: where
the image shows the needle tip against where the needle arm puts it (Table II's error, in
base_link, along the image's axes), and each tool tip against the reference tip the result located.
Each coordinate is divided by the SD the result itself measured for a new observation (its
leave-one-out RMSE / sqrt(3) for samples: annotation, beam, joint readings, the robot's error left
over and the calibration's own error; for touches its Table I RMSE / sqrt(3), or the whole chain's
touch noise SD if larger), and the sum of
squares is compared with the chi-square quantile at 1 - --false-alarm (default 5 % false alarms).

PASS (exit 0), or RECALIBRATE (exit 1) naming the part that most likely moved - needle tip, probe
mount, image transform, image scale (speed of sound) or robot (joint zeros): each is fitted to the
residuals alone and the one of largest Bayesian evidence is named, with how much it moved
(mm, degrees, %) and the targeting error it would cost if ignored. Without a probe touch the
samples cannot tell a probe remount from an image-transform change: both are named. Bad input:
exit 2. --out writes the verification record (JSON: result SHA-256, session files' SHA-256, date,
statistic, threshold, verdict, part, size); --report an HTML page of it.

--demo DIR writes a twin's calibration and two check sessions to try it: DIR/result.json,
DIR/check_unchanged (PASS) and DIR/check_probe_remounted (probe holder remounted by 1 mm / 1 deg:
RECALIBRATE).

example:
  brachycal verify --demo verify_demo
  brachycal verify verify_demo/result.json verify_demo/check_unchanged --out record.json --report record.html
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "verify", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("result", metavar="RESULT", nargs="?", help="calibration result (JSON)")
    parser.add_argument("check", metavar="CHECK_SESSION", nargs="?", help="check session folder")
    add_method_option(parser, "the result")
    rate = finite_float(low=0.0, high=0.5, low_open=True)
    parser.add_argument(
        "--false-alarm",
        type=rate,
        default=0.05,
        metavar="ALPHA",
        help=f"false-alarm rate of the test on an unchanged set-up, {rate.rule} (default 0.05)",
    )
    parser.add_argument("--out", metavar="JSON", help="verification record to write")
    parser.add_argument("--report", metavar="HTML", help="HTML page of the verification to write")
    parser.add_argument("--demo", metavar="DIR", help="write a twin's result and two check sessions into DIR")
    parser.add_argument("--force", action="store_true", help="replace existing outputs")
    add_robot_option(parser)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    if args.demo is not None:
        if args.result or args.check or args.out or args.report:
            raise InputError(
                "--demo writes its own result and check sessions: pass no RESULT, CHECK_SESSION, --out or --report"
            )
        return _demo(args)
    if not args.result or not args.check:
        raise InputError("give RESULT and CHECK_SESSION (or --demo DIR)")
    if not args.out:
        raise InputError("--out is required: the verification record a lab files")
    from brachycal.calibration import read_result
    from brachycal.calibration.check import check_calibration, outcome_json, read_check_session, verdict_text
    from brachycal.files import OutputSet, write_json

    out = Path(args.out)
    with OutputSet(force=args.force) as outputs:
        staged = outputs.claim(out, label="--out")
        staged_report = outputs.claim(Path(args.report), label="--report") if args.report else None
        stored = read_result(args.result)
        method = stored.method(args.method)
        robot = stored.software_robot(load_robot(args))
        session = read_check_session(args.check, robot)
        outcome = check_calibration(stored, method, robot, session, false_alarm=args.false_alarm)
        record = outcome_json(outcome, stored, session, robot)
        write_json(staged, record, force=args.force)
        if staged_report is not None:
            from brachycal.reporting.html_report import write_verification_page

            write_verification_page(staged_report, record, force=args.force)
    print(verdict_text(outcome))
    print("wrote " + ", ".join(map(str, outputs.written)))
    return 0 if outcome.passed else 1


def _demo(args: argparse.Namespace) -> int:
    """Twin seed 0 calibrated with the whole chain; two check sessions at ``plan --verify``'s poses."""
    import numpy as np

    from brachycal.files import OutputSet
    from brachycal.simulation.check_twin import (
        CHANGES,
        CalibratedTwin,
        changed_setup,
        record_check,
        write_check_session,
    )

    folder = Path(args.demo)
    robot = load_robot(args)
    with OutputSet(force=args.force) as outputs:
        staging = outputs.claim(folder / "result.json", make_parents=True)
        twin = CalibratedTwin(0, robot, staging.parent, result_path=staging)
        for name, change, seed in (
            ("unchanged", "unchanged", 1),
            ("probe_remounted", "probe remounted 1 mm / 1 deg", 2),
        ):
            rng = np.random.default_rng([0, seed, 7])
            setup = changed_setup(twin.twin, CHANGES[change], rng)
            session, _ = record_check(twin.twin, setup, twin.q_planned, twin.uv_planned, rng, touches=twin.touches)
            write_check_session(session, twin.twin, folder / f"check_{name}", robot, force=args.force, outputs=outputs)
    print(
        f"twin seed 0 calibrated (whole chain) and checked at {len(twin.q_planned)} poses of 'brachycal plan --verify' "
        f"plus single touches of rtip1 ({', '.join(twin.check_plan.touch_tools) or 'none'}; "
        f"{twin.check_plan.robot_minutes:.1f} robot minutes at 10 s per sample and 30 s per touch)"
    )
    print("wrote " + ", ".join(map(str, outputs.written)))
    return 0
