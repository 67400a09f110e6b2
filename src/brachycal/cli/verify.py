"""``brachycal verify``: is the stored calibration still good? A check of a few minutes before each procedure."""

from __future__ import annotations

import argparse
from pathlib import Path

from brachycal.cli.common import (
    add_method_option,
    add_quiet_option,
    add_robot_option,
    command_inputs,
    load_robot,
    method_said,
    output_file,
    print_next,
    robot_words,
)
from brachycal.cli.option_types import finite_float
from brachycal.errors import InputError

HELP = "check a stored calibration on a few new samples: PASS, or RECALIBRATE naming the part that moved"
DESCRIPTION = """\
Predicts each sample of CHECK_SESSION (a session folder with session.toml and samples.csv: the 8
poses of 'brachycal plan check', the needle tip annotated; optionally touches.csv with single
touches of the probe and/or the needle on a reference tip) from RESULT, and tests the residuals:
where the image shows the needle tip against where the needle arm puts it (Table II's error, in
base_link, along the image's axes), and each tool tip against the reference tip the result located.
Each coordinate is divided by the SD the result itself measured for a new observation (its
leave-one-out RMSE / sqrt(3) for samples, or at a repeated calibration pose that pose's own, see
--calibration-session; for touches its Table I RMSE / sqrt(3), or the whole chain's touch noise SD
if larger). Each part is fitted to the residuals alone; the check fails when the sum of squares
exceeds its chi-square quantile at 1 - ALPHA/2, or the chi-square one part explains exceeds its
quantile at 1 - ALPHA/(2 x parts): at most ALPHA (--false-alarm, default 5 %) false alarms in all.

PASS (exit 0), or RECALIBRATE (exit 1) naming the part that most likely moved - needle tip, probe
mount, image transform, image scale (speed of sound) or robot (joint zeros): each is fitted to the
residuals alone and the one of largest Bayesian evidence is named, with how much it moved
(mm, degrees, %) and the targeting error it would cost if ignored. Without a probe touch the
samples cannot tell a probe remount from an image-transform change: both are named. Bad input:
exit 2. --out writes the verification record (JSON: result SHA-256, session files' SHA-256, date,
statistic, threshold, verdict, part, size); --report an HTML page of it.

--update JSON: instead of recalibrating, where the check fails and one part (needle tip, probe
mount, image transform or image scale) alone explains it - fully determined, told apart from the
others by a Bayes factor of 20 or more, what it leaves within noise, a small change - writes the
stored result with that part changed by its fitted change and the change recorded (its SD says
how well the check determined it). Otherwise it says why and writes nothing there. Confirm an
update with a new check of fresh samples.

--calibration-session DIR (the session RESULT was calibrated from): a check pose that repeats one
of its poses gets that pose's own SD, the larger of the average and its leave-one-out error /
sqrt(3): the robot's left-over error is repeatable and largest at the cube's corners, where the
check's poses go. Without it every pose has the average (a warning says so).

--demo DIR writes a twin's calibration and sessions to try it: DIR/result.json, DIR/session (the
calibration session), DIR/check_unchanged (PASS) and DIR/check_probe_remounted (probe holder
remounted by 1 mm / 1 deg: RECALIBRATE).

example:
  brachycal verify --demo vdemo
  brachycal verify vdemo/result.json vdemo/check_unchanged --calibration-session vdemo/session --out vdemo.json
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
    parser.add_argument(
        "--calibration-session",
        metavar="DIR",
        help="the session folder RESULT was calibrated from: each check pose that repeats one of its poses gets "
        "that pose's own null SD (its leave-one-out error, where the robot's left-over error shows); without it "
        "every pose has the average, and false alarms run above --false-alarm on real arms",
    )
    parser.add_argument("--out", type=output_file, metavar="JSON", help="verification record to write")
    parser.add_argument(
        "--update",
        metavar="JSON",
        help="on RECALIBRATE, where one part alone explains the check and the check determines it, write the "
        "stored result with that part refitted (else say why not and write nothing there)",
    )
    parser.add_argument("--report", metavar="HTML", help="HTML page of the verification to write")
    parser.add_argument("--demo", metavar="DIR", help="write a twin's result and two check sessions into DIR")
    parser.add_argument("--force", action="store_true", help="replace existing outputs")
    add_quiet_option(parser, "next: line")
    add_robot_option(parser)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    if args.demo is not None:
        if args.result or args.check or args.out or args.report or args.calibration_session or args.update:
            raise InputError(
                "--demo writes its own result and sessions: pass no RESULT, CHECK_SESSION, --calibration-session, "
                "--out, --report or --update"
            )
        return _demo(args)
    if not args.result or not args.check:
        raise InputError("give RESULT and CHECK_SESSION (or --demo DIR)")
    if not args.out:
        raise InputError("--out is required: the verification record a lab files")
    from brachycal.calibration import read_result, verify_folder  # lazy: start-up (the command's run only)
    from brachycal.io import OutputSet, write_json  # lazy: start-up (the command's run only)

    out = Path(args.out)
    with OutputSet(force=args.force, inputs=command_inputs(args, "result", "check", "calibration_session")) as outputs:
        staged = outputs.claim(out, label="--out")
        staged_report = outputs.claim(Path(args.report), label="--report") if args.report else None
        staged_update = outputs.claim(Path(args.update), label="--update") if args.update else None
        check = verify_folder(
            args.result,
            args.check,
            calibration_session=args.calibration_session,
            method=args.method,
            robot=load_robot(args),
            false_alarm=args.false_alarm,
            update=staged_update is not None,
        )
        write_json(staged, check.record, force=args.force)
        if staged_report is not None:
            # lazy: start-up (the command's run only)
            from brachycal.reporting.html_report import write_verification_page

            write_verification_page(staged_report, check.record, force=args.force)
        if staged_update is not None:
            if check.updated is not None:
                write_json(staged_update, check.updated, force=args.force)
            else:
                outputs.release(Path(args.update))
    if not check.calibration_session:
        import warnings  # lazy: start-up (the command's run only)

        from brachycal.errors import BrachycalWarning  # lazy: start-up (the command's run only)

        warnings.warn(
            "no --calibration-session: every check pose had the average null SD; at the cube's corners the "
            "robot's left-over error is larger, and false alarms run above the stated rate on real arms",
            BrachycalWarning,
            stacklevel=1,
        )
    print(check.verdict_text())
    print(f"checked method: {method_said(read_result(args.result), args.method)}")
    if args.update and check.update_refusal is not None:
        print(f"no update written to {args.update}: {check.update_refusal}")
    elif args.update:
        part = check.outcome.part
        assert part is not None
        print(
            f"updated: the {part.part} refitted from the check, by {part.size_text()}; "
            f"confirm it with a new check of fresh samples before use"
        )
    print("wrote " + ", ".join(map(str, outputs.written)))
    if args.update and check.updated is not None:
        print(
            f"next: brachycal verify {args.update} FRESH_CHECK_SESSION --calibration-session SESSION --out check.json"
        )
    elif not check.passed:
        print(
            "next: recalibrate: record a session, then brachycal session build ... and brachycal calibrate SESSION "
            "--out result.json" + ("" if args.update else " (or, where one part alone explains the check, --update)")
        )
    return 0 if check.passed else 1


def _demo(args: argparse.Namespace) -> int:
    """Twin seed 0 calibrated with the whole chain; two check sessions at ``plan check``'s poses."""
    import numpy as np  # lazy: start-up (the command's run only)

    from brachycal.data.session import write_session  # lazy: start-up (the command's run only)
    from brachycal.io import OutputSet  # lazy: start-up (the command's run only)
    from brachycal.studies.check_twin import (  # lazy: start-up (the command's run only)
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
        write_session(twin.twin.session, folder / "session", force=args.force, outputs=outputs)
        for name, change, seed in (
            ("unchanged", "unchanged", 1),
            ("probe_remounted", "probe remounted 1 mm / 1 deg", 2),
        ):
            rng = np.random.default_rng([0, seed, 7])
            setup = changed_setup(twin.twin, CHANGES[change], rng)
            session, _ = record_check(twin.twin, setup, twin.q_planned, twin.uv_planned, rng, touches=twin.touches)
            write_check_session(session, twin.twin, folder / f"check_{name}", robot, force=args.force, outputs=outputs)
    print(
        f"twin seed 0 calibrated (whole chain) and checked at {len(twin.q_planned)} poses of 'brachycal plan check' "
        f"plus single touches of rtip1 ({', '.join(twin.check_plan.touch_tools) or 'none'}; "
        f"{twin.check_plan.robot_minutes:.1f} robot minutes at 10 s per sample and 30 s per touch)"
    )
    print("wrote " + ", ".join(map(str, outputs.written)))
    d, words = folder.as_posix(), robot_words(args)
    print_next(
        f"brachycal verify {d}/result.json {d}/check_unchanged --calibration-session {d}/session{words} "
        "--out check_unchanged.json",
        f"brachycal verify {d}/result.json {d}/check_probe_remounted --calibration-session {d}/session{words} "
        "--out check_remounted.json",
        quiet=args.quiet,
    )
    return 0
