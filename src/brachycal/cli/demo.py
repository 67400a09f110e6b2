"""``brachycal demo``: the main job on the bundled example — a full calibration on the digital twin.

Simulates a session with the paper's set-up (or loads the committed example), calibrates it
exactly as a lab would (from the session files), prints Tables I and II, and next to them the
end-to-end targeting error against the truth, then writes a report folder.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from brachycal.cli.common import add_robot_option, progress_bar, warn_refused
from brachycal.cli.option_types import bounded_int, seed
from brachycal.validate import MAX_TARGETS

HELP = "calibrate a simulated session (digital twin) and compare with the truth"
DESCRIPTION = """\
The main job on the bundled example: a digital twin of a calibration session with the paper's
set-up (SDA10F with a slightly different physical geometry, tools off their nominal frames,
encoder noise, jog error at the touches, 1 px annotation noise, the needle tip within the beam's
thickness, water's speed of sound), calibrated from its session files. Prints Table I, Table II
and the end-to-end targeting error against the truth, and writes DIR/session (the session and
its truth), DIR/result.json and DIR/report (figures and per-sample residuals). Table III compares,
on the same simulated robot, the tracker route: an N-wire phantom calibration and a hand-eye
calibration of the probe's marker with an optical tracker (NDI Polaris Spectra as in the paper:
0.25 mm RMS per marker, of which 0.1 mm jitter that 20 averaged frames per still pose reduce; wire
echoes from the beam's thickness, phantom print tolerance, landmark registration). One seed varies:
over seeds 0-9 the tracker route lands 0.49 +/- 0.13 mm (MAE, mean +/- SD over seeds), the paper's
Kabsch fusion 0.40 +/- 0.02 mm, the scaled u/v fusion 0.07 +/- 0.01 mm
(the documentation's Validation page, Table III).

Any robot with a description (--robot baxter, --robot ur5_pair, --robot FILE; docs/robots.md):
the twin plans in that robot's workspace and calibrates as on the SDA10F. The accuracy each
bundled robot reaches is in the documentation (Validation, Other robots).

The files are written together when the demo succeeded; an earlier demo's files in DIR are
replaced only with --force.

Table III complete (--table3): every method of the paper's Table III on the twin, over --seeds
seeds, with the spread and the paper's figure beside: the paper's fusion methods (ICP, Kabsch,
landmark/Horn), brachycal's whole chain, and the three phantom routes with an optical tracker
(N-wire, multi-wedge, arbitrary wire: src/brachycal/studies/phantom_twin.py states each
figure of their practice). Prints the table and writes nothing.

examples:
  brachycal demo                      simulate with seed 0 (= examples/twin_session)
  brachycal demo --table3 --seeds 3   Table III over seeds 0-2 (about 5 s a seed)
  brachycal demo --seed 7 --out demo_seed7         another simulated session
  brachycal demo --example --out demo_example      calibrate the committed examples/twin_session
  brachycal demo --robot baxter --out demo_baxter  the same main job on a Baxter
  brachycal demo --recording --check --out run --force   the twin's recordings: a session and two checks
"""


#: Seeds of ``--table3`` by default: about 5 s each on an idle core, within a minute or two.
TABLE3_SEEDS = 10


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "demo", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", default="demo_output", metavar="DIR", help="output folder (default demo_output)")
    parser.add_argument("--seed", type=seed, default=0, help=f"seed of the simulated session, {seed.rule} (default 0)")
    parser.add_argument("--example", action="store_true", help="use the committed examples/twin_session (the SDA10F's)")
    add_robot_option(parser)
    targets = bounded_int(low=1, high=MAX_TARGETS)
    parser.add_argument(
        "--targets", type=targets, default=50, help=f"targets for the targeting error, {targets.rule} (default 50)"
    )
    parser.add_argument("--force", action="store_true", help="replace the outputs of an earlier demo in DIR")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    seeds = bounded_int(low=1, high=100)
    parser.add_argument(
        "--table3",
        action="store_true",
        help="print Table III (fusion, whole chain, N-wire, multi-wedge, arbitrary wire) over --seeds seeds; "
        "writes nothing",
    )
    parser.add_argument(
        "--seeds", type=seeds, default=None, help=f"with --table3: seeds 0..N-1, {seeds.rule} (default 10)"
    )
    parser.add_argument(
        "--recording",
        action="store_true",
        help="also write DIR/recording: the twin's session as a lab records it (100 Hz joint log, marks.csv, "
        "images.csv, plan.csv, session.toml, a ROS 2 bag), for `brachycal session build`",
    )
    parser.add_argument(
        "--check",
        action="store_true",
        help="with --recording: also write the twin's check before a procedure as a lab records it, at the poses "
        "'brachycal plan check' picks from the recording's plan, with the probe's touch of rtip1: "
        "DIR/check_recording (nothing changed: PASS) and DIR/check_recording_remounted (the probe holder "
        "remounted by 1 mm / 1 deg: RECALIBRATE), for `brachycal session build --check`",
    )
    parser.add_argument(
        "--images",
        action="store_true",
        help="with --recording: also render its frames as B-mode images, DIR/recording/frames.mha (one per row "
        "of images.csv) and their true tips, frames_truth.csv, for `brachycal tips`",
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from brachycal.cli.common import load_robot  # lazy: start-up (the command's run only)
    from brachycal.io import OutputSet  # lazy: start-up (the command's run only)

    # lazy: start-up (the command's run only)
    from brachycal.reporting import DEMO_REPORT_FILES, demo_text, write_demo_report

    # lazy: start-up (the command's run only)
    from brachycal.simulation import TWIN_FILES, TwinConfig, record, write_recording
    from brachycal.studies import run_demo  # lazy: start-up (the command's run only)
    from brachycal.studies.demo import DEMO_STAGES  # lazy: start-up (the command's run only)

    start = time.perf_counter()
    from brachycal.studies.demo import check_example_robot  # lazy: start-up (the command's run only)

    for option in ("images", "check"):
        if getattr(args, option) and not args.recording:
            from brachycal.errors import InputError  # lazy: start-up (the command's run only)

            raise InputError(f"--{option} is part of the twin's recording: give --recording too")
    robot = load_robot(args)  # a bad description is refused before anything is claimed
    if args.table3:
        return _table3(args, robot, start)
    if args.seeds is not None:
        from brachycal.errors import InputError  # lazy: start-up (the command's run only)

        raise InputError("--seeds is the number of seeds of --table3: give --table3 too (or --seed for one session)")
    if args.example:
        check_example_robot(robot)
    out = Path(args.out)
    with OutputSet(force=args.force) as outputs:
        for name in TWIN_FILES:
            outputs.claim(out / "session" / name, make_parents=True)
        outputs.claim(out / "result.json", make_parents=True)
        for name in DEMO_REPORT_FILES:
            outputs.claim(out / "report" / name, make_parents=True)
        # The stages of run_demo, the report, and the recording if asked.
        with progress_bar(len(DEMO_STAGES) + 1 + args.recording + args.check, "demo", args.quiet, unit="stage") as bar:
            demo = run_demo(
                robot,
                out,
                seed=args.seed,
                example=args.example,
                n_targets=args.targets,
                outputs=outputs,
                progress=bar.update,
            )
            write_demo_report(demo, out / "report", outputs=outputs)
            bar.update(1)
            if args.recording:
                rec = record(robot, TwinConfig(seed=args.seed))
                from brachycal.simulation.bmode import BModeSettings  # lazy: start-up (the command's run only)

                images = BModeSettings(seed=args.seed) if args.images else None
                write_recording(rec, out / "recording", bag="sqlite3", images=images, force=args.force, outputs=outputs)
                bar.update(1)
            if args.check:
                # lazy: start-up (the command's run only)
                from brachycal.studies.check_twin import CHANGES, CHECK_RECORDINGS, check_recording

                for name, change, check_seed in CHECK_RECORDINGS:
                    check = check_recording(rec, robot, CHANGES[change], check_seed)
                    write_recording(check, out / name, force=args.force, outputs=outputs)
                bar.update(1)
        warn_refused(demo.result.refused)
        print(demo_text(demo))
    report = out / "report"
    print(
        f"\nwrote {out / 'session'} (session and truth), {out / 'result.json'}, {report}: "
        f"{', '.join(DEMO_REPORT_FILES)}"
    )
    if args.recording:
        rec_dir = out / "recording"
        print(
            f"wrote {rec_dir} (the twin's recording); build a session from it with:\n  brachycal session build "
            f"{rec_dir}/joint_log.csv --marks {rec_dir}/marks.csv --images {rec_dir}/images.csv "
            f"--plan {rec_dir}/plan.csv --template {rec_dir}/session.toml --out {out}/built_session"
            + (f" --robot {args.robot}" if args.robot is not None else "")
        )
        if args.check:
            robot_option = f" --robot {args.robot}" if args.robot is not None else ""
            for name, change, _ in CHECK_RECORDINGS:
                folder = out / name
                print(
                    f"wrote {folder} (the twin's check recording, {change}); build a check session from it with:\n"
                    f"  brachycal session build {folder}/joint_log.csv --check --marks {folder}/marks.csv "
                    f"--images {folder}/images.csv --plan {folder}/plan.csv --template {folder}/session.toml "
                    f"--out {out}/{name.replace('recording', 'session')}{robot_option}"
                )
        if args.images:
            print(
                f"its frames as B-mode images: {rec_dir}/frames.mha; propose the tips with:\n  brachycal tips "
                f"{rec_dir}/frames.mha --out {out}/images_detected.csv --sheet {out}/tips_sheet.png"
            )
    print(f"done in {time.perf_counter() - start:.1f} s")
    return 0


def _table3(args: argparse.Namespace, robot, start: float) -> int:
    """``--table3``: Table III over seeds 0..N-1, with a progress bar on stderr; no files."""
    from brachycal.errors import InputError  # lazy: start-up (the command's run only)
    from brachycal.studies.demo import table3, table3_text  # lazy: start-up (the command's run only)

    for option in ("example", "recording", "force"):
        if getattr(args, option):
            raise InputError(f"--table3 writes nothing and simulates its own sessions: drop --{option}")
    seeds = TABLE3_SEEDS if args.seeds is None else args.seeds
    with progress_bar(seeds, "Table III", args.quiet, unit="seed") as bar:
        table = table3(robot, range(seeds), args.targets, progress=bar.update)
    print(table3_text(table))
    print(f"done in {time.perf_counter() - start:.1f} s")
    return 0
