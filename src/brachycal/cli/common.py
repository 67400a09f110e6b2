"""Options and helpers shared by the sub-commands.

Light at import (argparse only): every sub-command module is imported to build ``brachycal --help``,
so the robot model and the progress bar are imported where they are used.
"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from tqdm import tqdm

    from brachycal.model import Robot


def add_urdf_option(parser: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    parser.add_argument(
        "--urdf",
        metavar="FILE",
        help="robot description to use instead of the bundled SDA10F (e.g. a calibrated URDF)",
    )


#: The robot descriptions brachycal ships (``src/brachycal/robots/*.toml``; docs/robots.md), named
#: here so that ``--help`` needs no file read.
BUNDLED_ROBOT_NAMES = ("sda10f", "baxter", "ur5_pair")


def add_robot_option(parser: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """``--robot NAME|FILE`` (with ``--urdf``, of which it is the general form)."""
    parser.add_argument(
        "--robot",
        metavar="NAME|FILE",
        help=f"robot description: a bundled one ({', '.join(BUNDLED_ROBOT_NAMES)}; default sda10f) or a "
        "brachycal-robot/1 TOML file (docs/robots.md)",
    )
    add_urdf_option(parser)


def load_robot(args: argparse.Namespace) -> Robot:
    """The robot of ``--robot`` (a description) or ``--urdf`` (an SDA10F URDF), default the bundled SDA10F.

    Raises:
        InputError: both given, or a description that does not load (one line naming file and key).
    """
    from brachycal.errors import InputError
    from brachycal.model import Robot

    name = getattr(args, "robot", None)
    if name is None:
        return Robot.load(args.urdf)
    if args.urdf is not None:
        raise InputError("--robot and --urdf both name the robot: pass one")
    from brachycal.model.description import load_description

    return load_description(name).robot


def tool_frame_parents(args: argparse.Namespace) -> dict[str, str]:
    """Each tool frame of the chosen robot with the link it is attached to."""
    name = getattr(args, "robot", None)
    if name is None:
        from brachycal.model import TOOL_FRAME_PARENTS

        return dict(TOOL_FRAME_PARENTS)
    from brachycal.model.description import load_description

    return load_description(name).tool_frame_parents


def progress_bar(total: int, desc: str, quiet: bool) -> tqdm:
    """A progress bar on stderr; hidden with --quiet and when stderr is not a terminal."""
    from tqdm import tqdm

    return tqdm(
        total=total,
        desc=desc,
        unit="sample",
        unit_scale=True,
        leave=False,
        file=sys.stderr,
        disable=True if quiet else None,
    )
