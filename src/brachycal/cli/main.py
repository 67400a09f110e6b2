"""The ``brachycal`` command: one sub-command per job, one-line errors with exit code 2.

Startup is kept short: every sub-command module is light at import (argparse only), and only the
sub-command being run builds its full parser (which imports the constants its options need) and
then imports what its run needs. ``brachycal --help`` imports no Pinocchio, SciPy, mink or matplotlib.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
import warnings
from collections.abc import Collection, Iterator, Sequence
from contextlib import contextmanager

from brachycal._version import __version__
from brachycal.cli import (
    calibrate,
    demo,
    design,
    examples,
    export,
    fk,
    locate,
    model,
    phantom,
    pivot,
    session,
    study,
    temporal,
    tips,
    verify,
    view,
)
from brachycal.cli import nwire as nwire_group
from brachycal.cli import plan as plan_group
from brachycal.cli import stepper as stepper_group
from brachycal.cli.nwire import calibrate as nwire
from brachycal.cli.nwire import segment as nwire_segment
from brachycal.cli.plan import check as plan_check
from brachycal.cli.plan import excitation as plan_excitation
from brachycal.cli.plan import grid as plan
from brachycal.cli.robot import identify as robot_identify
from brachycal.cli.stepper import calibrate as stepper
from brachycal.cli.stepper import export as stepper_export
from brachycal.cli.stepper import image as stepper_image
from brachycal.cli.stepper import template as stepper_template
from brachycal.errors import BrachycalError, OutputError

DESCRIPTION = """\
brachycal calibrates an ultrasound-guided dual-arm robot (Yaskawa SDA10F) for prostate
brachytherapy: the needle tip on the right flange, the probe tip on the left flange and the
ultrasound image on the probe. Units: metres and radians in files, unless a column name says
otherwise (u_px, mae_mm).

start here:
  brachycal demo                      calibrate the bundled example (a digital twin)
  brachycal examples examples         copy the example files the commands below can use into ./examples
  brachycal model                     joints, limits and tool frames of the robot model
  brachycal fk LOG --frames needle_tip,probe_tip --out poses.csv
                                      tool poses from a joint log (CSV or ROS bag)
  brachycal plan --out plan.csv        plan the 4x4x4 calibration sample poses
  brachycal session template DIR     blank session.toml, marks.csv and images.csv for a lab's own session
  brachycal session build LOG --marks marks.csv --images images.csv --template session.toml --out SESSION
                                      a session folder from a lab's recording (joint log, marks, frames)
  brachycal tips FRAMES.mha --out images.csv
                                      propose the needle tip in each B-mode frame (for session build)
  brachycal calibrate SESSION --out result.json
                                      calibrate a session folder (Tables I and II)
  brachycal locate RESULT JOINTS --uv U,V
                                      where an image pixel is in base_link
  brachycal export RESULT --out DIR   calibrated URDF, Slicer/ITK, PLUS and ROS files
  brachycal verify RESULT CHECK_SESSION --out record.json
                                      is the calibration still good? (a check before each procedure)
  brachycal view RESULT --session SESSION
                                      the calibrated session in 3D, in the browser
  brachycal pivot POSES.csv --out pivot.json
                                      pivot calibration of a tracked tool
  brachycal nwire [calibrate] CONFIG FRAMES --out nwire.json
                                      N-wire phantom calibration of a tracked probe (PLUS files)
  brachycal nwire segment CAL.mha VAL.mha --config CONFIG --out frames.xml
                                      the N-wire phantom's points in tracked B-mode sequences
  brachycal phantom wedge|wire|nwire GEOMETRY OBSERVATIONS --out result.json
                                      multi-wedge, arbitrary-wire or N-wire phantom calibration
  brachycal stepper [calibrate] ROTATION.mha PROBE_TRANSLATION.mha TEMPLATE_TRANSLATION.mha \\
      --config DEVICE_SET.xml --out stepper.json
                                      a TRUS probe's brachytherapy stepper: axes, pixel spacing, centre of rotation
  brachycal stepper image ROTATION.mha CAL.mha VAL.mha --config DEVICE_SET.xml --out stepper_image.json
                                      Image -> Probe of a TRUS probe on a stepper (random stepper motion)
  brachycal stepper template RESULT --config DEVICE_SET.xml --hole D4 --depth 100 --probe-position -50
                                      where a needle through a template hole lands in the image
  brachycal stepper export RESULT --out DIR
                                      a stepper result as PLUS CoordinateDefinitions and Slicer/ITK files
  brachycal temporal VIDEO.mha TRACKER.mha --out lag.json
                                      lag of the tracker (or joint log) behind the ultrasound frames
  brachycal robot identify touches FOLDER... --robot ARM --tool-frame FRAME --train PLACE --out DIR
                                      an arm's joint geometry from touches of fixed points
  brachycal robot identify tracker TABLE --columns SPEC --robot ARM --out DIR
                                      an arm's joint geometry from a tracker's marker measurements
  brachycal robot identify session SESSION --out DIR
                                      the dual-arm rig's joint geometry from its calibration session
  brachycal study --out DIR           how many samples? truth error vs LOO on the twin
  brachycal design --out DIR          which sample design gives most accuracy per robot minute
"""


class OneLineParser(argparse.ArgumentParser):
    """argparse, but a usage error is one line (what is wrong, and where to read more), exit code 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see {self.prog} --help)\n")


COMMANDS = {
    "demo": demo,
    "model": model,
    "fk": fk,
    "plan": plan,
    plan_check.NAME: plan_check,
    plan_excitation.NAME: plan_excitation,
    "session": session,
    "calibrate": calibrate,
    "locate": locate,
    "export": export,
    "pivot": pivot,
    "nwire": nwire,
    nwire_segment.NAME: nwire_segment,
    "phantom": phantom,
    "stepper": stepper,
    stepper_image.NAME: stepper_image,
    stepper_template.NAME: stepper_template,
    stepper_export.NAME: stepper_export,
    "temporal": temporal,
    "study": study,
    "design": design,
    "view": view,
    "verify": verify,
    "examples": examples,
    "tips": tips,
    robot_identify.NAME: robot_identify,
}


#: Two-word commands: ``brachycal nwire segment …`` is the command ``nwire-segment``, ``brachycal plan check …``
#: the command ``plan-check``; ``brachycal nwire calibrate …`` is ``brachycal nwire …``.
TWO_WORD_COMMANDS = {
    **{("nwire", word): name for word, name in nwire_group.SUBCOMMANDS.items()},
    **{("plan", word): name for word, name in plan_group.SUBCOMMANDS.items()},
    **{("stepper", word): name for word, name in stepper_group.SUBCOMMANDS.items()},
}
#: Each command group (``plan``, ``nwire``) with its sub-commands' words: ``brachycal --help`` lists the group
#: once, naming them, and not the sub-commands' own names.
GROUPS = {
    group: [word for (g, word), name in TWO_WORD_COMMANDS.items() if g == group and name != group]
    for group, _ in TWO_WORD_COMMANDS
}


def build_parser(full: Collection[str] | None = None) -> argparse.ArgumentParser:
    """The command's parser.

    Args:
        full: the sub-commands whose own parser (options, their rules and defaults) is built; the
            others get a stand-in with their one-line help, enough for ``brachycal --help`` and for
            naming the command. None: all of them (for looking at every option).
    """
    parser = OneLineParser(
        prog="brachycal", description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--version", action="version", version=f"brachycal {__version__}")
    sub = parser.add_subparsers(title="commands", metavar="COMMAND", required=True, parser_class=OneLineParser)
    for name, module in COMMANDS.items():
        if full is None or name in full:
            module.add_parser(sub)
        else:
            sub.add_parser(name, help=module.HELP)
    # One line per command group: a sub-command is listed under its group, not by its own name.
    # (argparse keeps the listing in a private list: `_choices_actions`, one entry per named parser.)
    listed_under_group = set(TWO_WORD_COMMANDS.values()) - set(GROUPS)
    shown = []
    for entry in sub._choices_actions:
        if GROUPS.get(entry.dest):
            entry.help = f"{entry.help}; also {', '.join(f'{entry.dest} {word}' for word in GROUPS[entry.dest])}"
        if entry.dest not in listed_under_group:
            shown.append(entry)
    sub._choices_actions[:] = shown
    return parser


def _command(argv: Sequence[str]) -> str | None:
    """The sub-command ``argv`` names: its first word that is not an option (the command's own
    options, --help and --version, take no value), or None."""
    return next((word for word in argv if not word.startswith("-")), None)


class Terminated(BaseException):
    """SIGTERM, raised in the main thread so that staged outputs are removed as on Ctrl-C."""


def _raise_terminated(signum: int, frame: object) -> None:
    raise Terminated


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"brachycal: warning: {' '.join(str(message).split())}", file=sys.stderr)


@contextmanager
def _command_environment() -> Iterator[None]:
    """What the command line (and only it) sets for the process: one-line warnings, SIGTERM, and
    the record of the input files read (an output may never be one of them)."""
    from brachycal.inputs import recording_inputs  # lazy: start-up (the command's run only)

    in_main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _raise_terminated) if in_main_thread else None
    with warnings.catch_warnings(), recording_inputs():
        warnings.showwarning = _show_warning
        warnings.simplefilter("default")
        # Library chatter a user cannot act on (NumPy on a refused input, parser notices).
        warnings.filterwarnings("ignore", category=RuntimeWarning)
        # A file left open by an interrupted import or by a library: a developer's concern, not
        # the user's (Python hides these by default; "default" above would show them).
        warnings.filterwarnings("ignore", category=ResourceWarning)
        try:
            yield
        finally:
            if in_main_thread:
                signal.signal(signal.SIGTERM, previous)


def joined_command(arguments: list[str]) -> list[str]:
    """``arguments`` with a two-word command (:data:`TWO_WORD_COMMANDS`) joined into its one name (and an
    earlier release's spelling of one, or of a phantom kind, made current)."""
    arguments = phantom.current_spelling(nwire_group.current_spelling(plan_group.current_spelling(arguments)))
    words = [k for k, word in enumerate(arguments) if not word.startswith("-")][:2]
    if len(words) == 2 and words[1] == words[0] + 1:
        name = TWO_WORD_COMMANDS.get((arguments[words[0]], arguments[words[1]]))
        if name is not None:
            return [*arguments[: words[0]], name, *arguments[words[1] + 1 :]]
    return arguments


def main(argv: Sequence[str] | None = None) -> int:
    try:
        arguments = joined_command(sys.argv[1:] if argv is None else list(argv))
        command = _command(arguments)
        args = build_parser(full=() if command is None else (command,)).parse_args(arguments)
    except SystemExit as exc:  # --help, --version, or a usage error (already printed, one line)
        return exc.code if isinstance(exc.code, int) else 2
    try:
        with _command_environment():
            return int(args.run(args) or 0)
    except OutputError as exc:  # its advice in the command line's words
        print(f"brachycal: error: {exc.spelled('--force')}", file=sys.stderr)
        return 2
    except BrachycalError as exc:
        print(f"brachycal: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        # The reader went away (e.g. `| head`): stop quietly, as Unix tools do.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141
    except OSError as exc:
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"brachycal: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except RecursionError:  # a reader that does not name its file: still one line, no traceback
        print("brachycal: error: an input is nested too deeply to read", file=sys.stderr)
        return 2
    except MemoryError:
        print("brachycal: error: out of memory (ask for less: fewer points, samples or targets)", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("brachycal: interrupted", file=sys.stderr)
        return 130
    except Terminated:
        print("brachycal: terminated", file=sys.stderr)
        return 143


if __name__ == "__main__":
    sys.exit(main())
