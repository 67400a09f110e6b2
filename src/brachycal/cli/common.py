"""Options and helpers shared by the sub-commands."""

from __future__ import annotations

import argparse
import sys

from tqdm import tqdm

from brachycal.model import Robot


def add_urdf_option(parser: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    parser.add_argument(
        "--urdf",
        metavar="FILE",
        help="robot description to use instead of the bundled SDA10F (e.g. a calibrated URDF)",
    )


def load_robot(args: argparse.Namespace) -> Robot:
    return Robot.load(args.urdf)


def progress_bar(total: int, desc: str, quiet: bool) -> tqdm:
    """A progress bar on stderr; hidden with --quiet and when stderr is not a terminal."""
    return tqdm(
        total=total,
        desc=desc,
        unit="sample",
        unit_scale=True,
        leave=False,
        file=sys.stderr,
        disable=True if quiet else None,
    )
