"""``brachycal calibrate``: the paper's calibration of a session, Tables I and II, result file."""

from __future__ import annotations

import argparse
import gc
from contextlib import nullcontext
from pathlib import Path

from brachycal.cli.common import (
    add_quiet_option,
    add_robot_accuracy_options,
    add_robot_option,
    load_robot,
    method_said,
    output_file,
    print_next,
    progress_bar,
    robot_accuracy,
    robot_words,
    spelling_note,
    stage_lines,
    warn_refused,
)
from brachycal.cli.option_types import bounded_int, name_list
from brachycal.errors import InputError

#: Most bootstrap refits --bootstrap takes: a 95% percentile interval is settled by ~2000; 10000
#: refits of the chain already take hours, so a larger count is a typo.
MAX_BOOTSTRAP = 10_000

HELP = "calibrate a session: tool tips, tool rotations, image-to-probe; prints Tables I and II"
DESCRIPTION = """\
Runs the mechanism-image fusion calibration on a session folder (format brachycal-session/1:
session.toml, touches.csv, axes.csv, samples.csv): reference tips with the top-model, the needle
and probe tips (Table I, validated at rtip2), the tool rotations from three points, and the
image-to-probe transform by ICP, Kabsch, Horn ("Landmark"), a similarity fit and a fit with
separate u/v pixel spacings, each evaluated by leave-one-out cross-validation (Table II).

With --solve chain, the whole chain is also solved as one least-squares problem over all the
data (touches, axes moves, images; gross image outliers flagged and left out), the image model
(rigid, similarity, scaled u/v, or speed of sound) chosen by cross-validation, with 95% intervals
of the session's noise and the robot's stated kinematic accuracy (--robot-accuracy-mm/-deg;
coverage on the twin: the documentation's Validation page) and the predicted landing error
over the sample poses and the image; data that cannot determine the chain
are refused. The result then carries the chain's transforms.

With --solve chain --identify-robot, the robot's own geometry (every joint origin's small
translation and rotation, zero offsets included) is identified jointly with the chain from the
same session, the stated accuracy (--robot-accuracy-mm/-deg: state the arm's real figures) as its
prior; the result carries the corrections, which 'brachycal export' writes into the calibrated
URDF and 'locate', 'plan' and 'export' apply exactly once. It prints which parameters the session
cannot identify and why, the image error at held-out configurations with and without it, and the
verdict: use the identified robot (its held-out gain exceeds twice its standard error over the
folds) or keep the URDF. It refits the chain and the robot nine times (once, then once per held-out
fold): about 4 s for a 64-sample session on a free core (1 s without it), more while other programs run; in
a terminal a line per stage shows the progress (--quiet: none).

The robot is the SDA10F unless --robot names another description (baxter, ur5_pair, or a TOML
file: docs/robots.md); the session's joint columns must be that robot's. The result records it
(its "robot" block), and 'locate' and 'export' refuse another robot.

A registration method that the samples cannot determine (e.g. ICP on a symmetric pattern of
needle positions that the URDF's nominal image frame cannot resolve) is refused alone: Table II
says why, the result records it under "refused", a warning line names it, and the other methods
and the chain go ahead. Only when every method asked for (--methods) refuses is the command refused.

The result (brachycal-result/1, JSON, metres) and the report are written together, all or
nothing, when everything succeeded; neither replaces an existing file without --force.

example:
  brachycal calibrate examples/twin_session --out twin_result.json
"""


#: The values of --solve: the paper's steps one after another, or the whole chain at once as well.
SOLVES = ("sequential", "chain")


def _old_solve(text: str) -> str:
    """argparse type of calibrate's earlier ``--method sequential|chain`` (now ``--solve``): an image
    method there (kabsch, chain+robot, ...) is refused saying which option does what was meant."""
    if text in SOLVES:
        return text
    from brachycal.calibration.labels import ALL_LABELS, METHODS  # lazy: start-up (the command's run only)

    if text == "chain+robot":
        hint = "to solve the chain with the robot's geometry use --solve chain --identify-robot"
    elif text in ALL_LABELS:
        hint = f"to fit only {text} use --methods {text}" if text in METHODS else f"to solve it use --solve {text}"
    else:
        hint = f"{text!r} is none of them (methods: {', '.join(METHODS)})"
    raise argparse.ArgumentTypeError(
        f"calibrate fits every method of --methods and --solve sequential|chain says how; {hint}"
    )


def add_parser(sub: argparse._SubParsersAction) -> None:
    from brachycal.calibration.labels import METHODS  # lazy: start-up (the command's run only)

    parser = sub.add_parser(
        "calibrate", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("session", metavar="SESSION", help="session folder")
    parser.add_argument("--out", required=True, type=output_file, metavar="JSON", help="result file to write")
    parser.add_argument(
        "--methods",
        type=name_list(METHODS),
        default=",".join(METHODS),
        metavar="A,B",
        help=f"image methods to fit (registrations), each once (default all: {','.join(METHODS)})",
    )
    parser.add_argument(
        "--solve",
        choices=SOLVES,
        help="sequential: the paper's steps, one part after another (default); chain: also one least-squares "
        "problem over all the data, image model chosen by cross-validation, with uncertainty",
    )
    # The earlier spelling of --solve (a "method" is an image transform's: docs/glossary.md).
    parser.add_argument("--method", dest="old_solve", type=_old_solve, help=argparse.SUPPRESS)
    parser.add_argument(
        "--joint-offsets",
        action="store_true",
        help="with --solve chain: also estimate the joint zero offsets this session identifies",
    )
    add_robot_accuracy_options(
        parser,
        "with --solve chain",
        zero=True,
        note="; included in the intervals and the predicted landing error",
    )
    parser.add_argument(
        "--identify-robot",
        action="store_true",
        help="with --solve chain: also identify the robot's geometry from the session (the stated "
        "accuracy is its prior); replaces --joint-offsets",
    )
    replicates = bounded_int(low=0, high=MAX_BOOTSTRAP)
    parser.add_argument(
        "--bootstrap",
        type=replicates,
        default=0,
        metavar="N",
        help=f"with --solve chain: N bootstrap refits for percentile intervals, {replicates.rule} (default 0)",
    )
    add_robot_option(parser)
    parser.add_argument("--force", action="store_true", help="replace --out if it exists")
    add_quiet_option(parser)
    parser.add_argument("--report", metavar="DIR", help="also write a self-contained HTML report (DIR/report.html)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    # The imports create some 50k objects that live as long as the process: no collection can free
    # any of them (they cost ~30 ms of collections otherwise). The computation's own garbage is
    # collected as usual, those objects left out (frozen_heap). This command owns its process.
    collecting = gc.isenabled()
    gc.disable()
    try:
        return _run(args, collecting)
    finally:
        if collecting:
            gc.enable()


def _solve(args: argparse.Namespace) -> str:
    """--solve's value, or the earlier spelling --method's (with a note on stderr); sequential if neither."""
    if args.old_solve is None:
        return args.solve or "sequential"
    if args.solve is not None and args.solve != args.old_solve:
        raise InputError(f"--solve {args.solve} and --method {args.old_solve} disagree: give --solve alone")
    spelling_note(f"calibrate --method {args.old_solve}", f"calibrate --solve {args.old_solve}")
    return args.old_solve


def _run(args: argparse.Namespace, collecting: bool) -> int:
    from brachycal.calibration import calibrate_folder, read_result, write_result  # lazy: start-up (run only)
    from brachycal.calibration.parallel import forking_workers, frozen_heap  # lazy: start-up (the command's run only)
    from brachycal.io import OutputSet  # lazy: start-up (the command's run only)

    # lazy: start-up (the command's run only)
    from brachycal.reporting import chain_summary, table_i, table_ii, uncertainty_table

    solve = _solve(args)
    if solve != "chain" and (args.bootstrap or args.joint_offsets or args.identify_robot):
        option = "--bootstrap" if args.bootstrap else "--joint-offsets" if args.joint_offsets else "--identify-robot"
        raise InputError(f"{option} needs --solve chain (the sequential method has no bootstrap or robot terms)")
    if args.identify_robot and args.joint_offsets:
        raise InputError("--identify-robot replaces --joint-offsets (it identifies the zero offsets too): pass one")
    if solve != "chain" and (args.robot_accuracy_mm is not None or args.robot_accuracy_deg is not None):
        option = "--robot-accuracy-mm" if args.robot_accuracy_mm is not None else "--robot-accuracy-deg"
        raise InputError(f"{option} needs --solve chain (the sequential method states no robot term)")
    with OutputSet(force=args.force, inputs=[args.session]) as outputs:
        staged_result = outputs.claim(args.out, label="--out")
        if args.report:
            # Here, not at the top: the report's figures load matplotlib (~0.5 s), for --report only.
            from brachycal.reporting import report_files, write_report  # lazy: start-up (the command's run only)

            for name in report_files(solve == "chain"):
                outputs.claim(Path(args.report) / name, make_parents=True, label=f"--report's {name}")
        robot = load_robot(args)
        # This command owns its process: its independent refits may share the cores (forked workers).
        # The bar only with --bootstrap: tqdm's monitor thread, started by any bar, rules out forking.
        bar_context = (
            progress_bar(args.bootstrap, "bootstrap", args.quiet, unit="resample") if args.bootstrap else nullcontext()
        )
        with forking_workers(), frozen_heap(), bar_context as bar:
            if collecting:
                gc.enable()
            calibrated = calibrate_folder(
                args.session,
                robot,
                tuple(args.methods),  # checked by argparse: known, none empty, no repeats
                chain=solve == "chain",
                bootstrap_replicates=args.bootstrap,
                joint_offsets=args.joint_offsets,
                progress=None if bar is None else bar.update,
                robot_accuracy=robot_accuracy(args),
                identify_robot=args.identify_robot,
                stage=stage_lines(args.quiet),
            )
        result, chain, session = calibrated.result, calibrated.chain, calibrated.session
        warn_refused(result.refused)
        print(table_i(result))
        print()
        print(table_ii(result, chain.loocv if chain else None))
        print()
        print(uncertainty_table(result))
        if chain is not None:
            print()
            print(chain_summary(chain, session.sample_ids, sector=session.sector, spacing_m=session.spacing_m))
        write_result(
            result,
            staged_result,
            force=args.force,
            chain=chain,
            robot=robot,
        )
        if args.report:
            write_report(
                args.report, result, session, robot, str(args.session), chain, force=args.force, outputs=outputs
            )
    if args.report:
        print(f"report: {Path(args.report) / 'report.html'}")
    print(f"\nwrote {args.out}")
    # Read back: the rule is the result file's own (locate, export, view, plan use it the same way).
    print(f"the next commands use: {method_said(read_result(args.out), None)}")
    words = robot_words(args)
    print_next(
        f"brachycal locate {args.out} JOINTS --uv U,V{words}",
        f"brachycal export {args.out}{words} --out DIR",
        quiet=args.quiet,
    )
    return 0
