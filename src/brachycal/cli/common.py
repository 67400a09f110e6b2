"""Options and helpers shared by the sub-commands.

Light at import (argparse only): every sub-command module is imported to build ``brachycal --help``,
so the robot model and the progress bar are imported where they are used.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable, Collection, Sequence
from typing import TYPE_CHECKING, TextIO

if TYPE_CHECKING:
    from tqdm import tqdm

    from brachycal.calibration.robot_accuracy import RobotAccuracy
    from brachycal.calibration.session.result_file import ResultFile
    from brachycal.model import Robot


def output_file(text: str) -> str:
    """argparse type of an output that is one file (``--out poses.csv``): a path ending in a separator
    names a folder, and ``Path`` would drop the separator and write a file of the folder's name."""
    if not text or text.endswith(("/", os.sep)) or (os.altsep and text.endswith(os.altsep)):
        raise argparse.ArgumentTypeError(f"{text!r} names a folder; give the file to write")
    return text


def spelling_note(old: str, new: str) -> None:
    """Say on stderr, in one line, that an earlier release's spelling ``old`` of a command is now ``new``."""
    print(f"brachycal: note: '{old}' is now '{new}'; the old spelling goes in the next release", file=sys.stderr)


def earlier_spelling(arguments: Sequence[str], command: str, current: Collection[str]) -> int | None:
    """Where ``command`` is in ``arguments`` (after ``brachycal``, an index) when they run it without one
    of its ``current`` sub-command words right after it (perhaps an earlier release's spelling); None
    when they run another command or spell it the current way."""
    words = [k for k, word in enumerate(arguments) if not word.startswith("-")]
    if not words or arguments[words[0]] != command:
        return None
    if len(words) > 1 and words[1] == words[0] + 1 and arguments[words[1]] in current:
        return None  # the current spelling
    return words[0]


def add_urdf_option(parser: argparse.ArgumentParser | argparse._ArgumentGroup, *, any_arm: bool = False) -> None:
    """``--urdf FILE``: a URDF of any robot (``any_arm``), or an SDA10F URDF for the dual-arm commands."""
    parser.add_argument(
        "--urdf",
        metavar="FILE",
        help="URDF file of any robot (as --robot FILE.urdf), instead of the bundled SDA10F"
        if any_arm
        else "SDA10F URDF to use instead of the bundled one (e.g. a calibrated URDF); another robot: --robot",
    )


#: The robot descriptions brachycal ships (``src/brachycal/robots/*.toml``; docs/robots.md), named
#: here so that ``--help`` needs no file read: the dual-arm rigs, and the single arms.
BUNDLED_ROBOT_NAMES = ("sda10f", "baxter", "ur5_pair")
SINGLE_ARM_ROBOT_NAMES = ("panda", "ur5", "ur10")


def add_robot_option(parser: argparse.ArgumentParser | argparse._ArgumentGroup, *, any_arm: bool = False) -> None:
    """``--robot NAME|FILE`` (with ``--urdf``, of which it is the general form).

    ``any_arm``: the command takes any robot (a single arm, a plain URDF), not only a dual-arm rig
    (see :func:`load_robot`).
    """
    if any_arm:
        names = ", ".join(BUNDLED_ROBOT_NAMES + SINGLE_ARM_ROBOT_NAMES)
        what = (
            f"any robot: a bundled description ({names}; default sda10f), a brachycal-robot/1 TOML file or a URDF file"
        )
    else:
        names = ", ".join(BUNDLED_ROBOT_NAMES)
        what = (
            f"a dual-arm robot (a needle arm and a probe arm): a bundled description ({names}; default sda10f) or a "
            "brachycal-robot/1 TOML file"
        )
    parser.add_argument("--robot", metavar="NAME|FILE", help=f"{what} (docs/robots.md)")
    add_urdf_option(parser, any_arm=any_arm)


def command_inputs(args: argparse.Namespace, *names: str) -> list[str]:
    """The input files (or folders) the options ``names`` of ``args`` give, with ``--robot`` and
    ``--urdf``: declared to the command's :class:`~brachycal.io.OutputSet`, so that an output
    naming one of them is refused before any work."""
    values = [getattr(args, name, None) for name in (*names, "robot", "urdf")]
    return [value for value in values if isinstance(value, str)]


def load_robot(args: argparse.Namespace, *, any_arm: bool = False) -> Robot:
    """The robot of ``--robot`` (a description or a URDF file) or ``--urdf`` (a URDF), default the
    bundled SDA10F.

    Unless ``any_arm``, the robot must be a dual-arm rig (a needle arm and a probe arm): checked
    here, before any work, so that a single arm or another robot's URDF is refused in one line.

    Raises:
        InputError: both given, a description that does not load (one line naming file and key), or
            (not ``any_arm``) a robot without a needle arm and a probe arm.
    """
    from brachycal.errors import InputError  # lazy: start-up (the command's run only)
    from brachycal.model import Robot  # lazy: start-up (the command's run only)

    name = getattr(args, "robot", None)
    if name is None:
        robot = Robot.load(args.urdf)
    elif args.urdf is not None:
        raise InputError("--robot and --urdf both name the robot: pass one")
    else:
        from brachycal.model.description import load_robot as load  # lazy: start-up (the command's run only)

        robot = load(name)
    if not any_arm:
        _ = robot.rig  # refuses a robot without a needle arm and a probe arm, in one line
    return robot


def print_next(*commands: str, quiet: bool = False) -> None:
    """The ``next:`` line: the command to run next (a whole ``brachycal ...`` command, placeholders in
    capitals), and each further one (the step after it, or another the user may want) on a line of its
    own below it, aligned; nothing with --quiet."""
    if quiet or not commands:
        return
    first, *others = commands
    print(f"next: {first}")
    for command in others:
        print(f"      {command}")


def robot_words(args: argparse.Namespace) -> str:
    """The robot options of ``args`` as a next command repeats them (`` --robot NAME``, `` --urdf FILE``
    or nothing for the default robot), for :func:`print_next`."""
    robot, urdf = getattr(args, "robot", None), getattr(args, "urdf", None)
    return f" --robot {robot}" if robot else f" --urdf {urdf}" if urdf else ""


def add_quiet_option(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup, hides: str = "progress and no next: line"
) -> None:
    """``--quiet``, every command's that writes outputs: it shows less (``hides``, what the command then
    leaves out: its progress, its ``next:`` line (:func:`print_next`), a report); errors, warnings and
    the files written are still printed."""
    parser.add_argument("--quiet", action="store_true", help=f"no {hides}")


def progress_bar(total: int | None, desc: str, quiet: bool, *, unit: str) -> tqdm:
    """A progress bar on stderr counting ``total`` ``unit`` (whole counts: "3/10 twin"; bytes, unit
    ``"B"``, in kB/MB; ``total`` ``None``: a count without an end, for work of unknown size); hidden
    with --quiet and when stderr is not a terminal."""
    from tqdm import tqdm  # lazy: start-up (the command's run only)

    return tqdm(
        total=total,
        desc=desc,
        unit=unit,
        unit_scale=unit == "B",
        leave=False,
        file=sys.stderr,
        disable=True if quiet else None,
    )


def stage_lines(quiet: bool, stream: TextIO | None = None) -> Callable[[str], None] | None:
    """Progress as one line per stage of a long computation, on ``stream`` (stderr), each with the
    seconds since the start (``brachycal: [12 s] held-out configurations: fold 3 of 8``): for work that
    forks worker processes, where a bar's monitor thread must not run. As the bars: None (nothing
    shown) with --quiet and when the stream is not a terminal."""
    import time  # lazy: start-up (the command's run only)

    stream = sys.stderr if stream is None else stream
    if quiet or not stream.isatty():
        return None
    start = time.monotonic()

    def say(line: str) -> None:
        print(f"brachycal: [{time.monotonic() - start:.0f} s] {line}", file=stream, flush=True)

    return say


def add_robot_accuracy_options(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup,
    when: str,
    *,
    zero: bool,
    note: str = "",
    default: RobotAccuracy | None = None,
) -> None:
    """``--robot-accuracy-mm`` and ``--robot-accuracy-deg``: the robot's stated kinematic accuracy.

    Args:
        parser: where to add them.
        when: the option they go with, for the help (``"with --solve chain"``).
        zero: whether 0 (a perfect robot) is allowed; a prior of identification must be positive.
        note: what the accuracy is used for, appended to the millimetres' help.
        default: the command's own default, when not the general one (DEFAULT_ROBOT_ACCURACY).
    """
    import numpy as np  # lazy: start-up (the command's run only)

    from brachycal.calibration.robot_accuracy import (  # lazy: start-up (the command's run only)
        DEFAULT_ROBOT_ACCURACY,
        MAX_ROBOT_ROTATION_SD_RAD,
        MAX_ROBOT_TRANSLATION_SD_M,
    )
    from brachycal.cli.option_types import finite_float  # lazy: start-up (the command's run only)

    general = default is None
    default = DEFAULT_ROBOT_ACCURACY if default is None else default
    millimetres = finite_float(low=0.0, high=MAX_ROBOT_TRANSLATION_SD_M * 1e3, low_open=not zero, unit="mm")
    parser.add_argument(
        "--robot-accuracy-mm",
        type=millimetres,
        metavar="SD",
        help=f"{when}: the robot's stated accuracy, each joint origin's translation SD per axis, "
        f"{millimetres.rule} (default {default.translation_sd_m * 1e3:g}"
        + (", a well-built arm; real arms are often 0.1)" if general else ")")
        + note,
    )
    degrees = finite_float(low=0.0, high=float(np.degrees(MAX_ROBOT_ROTATION_SD_RAD)), low_open=not zero, unit="deg")
    parser.add_argument(
        "--robot-accuracy-deg",
        type=degrees,
        metavar="SD",
        help=f"{when}: each joint origin's rotation SD per axis and zero-offset SD, "
        f"{degrees.rule} (default {np.degrees(default.rotation_sd_rad):g}"
        + ("; real arms often 0.01)" if general else ")"),
    )


def robot_accuracy(args: argparse.Namespace, default: RobotAccuracy | None = None) -> RobotAccuracy:
    """The stated robot accuracy: the options given, the command's defaults for the others.

    Args:
        args: the parsed ``--robot-accuracy-mm`` and ``--robot-accuracy-deg``.
        default: the command's own default (as given to :func:`add_robot_accuracy_options`);
            None for the general one (DEFAULT_ROBOT_ACCURACY).
    """
    import numpy as np  # lazy: start-up (the command's run only)

    # lazy: start-up (the command's run only)
    from brachycal.calibration.robot_accuracy import DEFAULT_ROBOT_ACCURACY, RobotAccuracy

    default = DEFAULT_ROBOT_ACCURACY if default is None else default
    if args.robot_accuracy_mm is None and args.robot_accuracy_deg is None:
        return default
    mm = args.robot_accuracy_mm if args.robot_accuracy_mm is not None else default.translation_sd_m * 1e3
    deg = args.robot_accuracy_deg if args.robot_accuracy_deg is not None else float(np.degrees(default.rotation_sd_rad))
    return RobotAccuracy(
        mm * 1e-3,
        float(np.radians(deg)),
        default.encoder_sd_rad,
        f"--robot-accuracy-mm {mm:g} --robot-accuracy-deg {deg:g} (encoder SD: the default)",
    )


def add_method_option(parser: argparse.ArgumentParser | argparse._ArgumentGroup, of: str) -> None:
    """``--method``: which image calibration of a result (:meth:`ResultFile.method
    <brachycal.calibration.session.result_file.ResultFile.method>`; default the result's best)."""
    from brachycal.calibration.labels import ALL_LABELS  # lazy: start-up (the command's run only)

    parser.add_argument(
        "--method",
        choices=tuple(ALL_LABELS),
        help=f"which image calibration of {of} (default: the result's best: chain+robot, then chain, else the "
        "lowest leave-one-out RMSE)",
    )


def method_said(stored: ResultFile, asked: str | None) -> str:
    """Which image calibration of ``stored`` a command uses, and why, in words: ``asked`` (the
    --method value) or, for None, the result's best (:meth:`ResultFile.best_method
    <brachycal.calibration.session.result_file.ResultFile.best_method>`) with the rule that chose it."""
    method = stored.method(asked)
    if asked is not None:
        return f"{method} (--method)"
    from brachycal.calibration.result import best_reason  # lazy: start-up (the command's run only)

    loocv = stored.raw.get("loocv")
    entry = loocv.get(method) if isinstance(loocv, dict) else None
    why = best_reason(method, entry.get("rmse_mm") if isinstance(entry, dict) else None)
    return f"{method} (the result's best: {why}; another with --method)"


def warn_refused(refused: dict[str, str]) -> None:
    """One warning line per registration method that refused the samples (a result's ``refused``):
    the calibration went ahead with the others, and Table II and the result file say why."""
    import warnings  # lazy: start-up (the command's run only)

    from brachycal.errors import BrachycalWarning  # lazy: start-up (the command's run only)

    for method, reason in refused.items():
        warnings.warn(
            f"{method} refused these samples and was left out (the other methods went ahead; Table II and the "
            f"result record why): {reason}",
            BrachycalWarning,
            stacklevel=2,
        )
