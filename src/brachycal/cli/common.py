"""Options and helpers shared by the sub-commands."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable

import numpy as np
from tqdm import tqdm

from brachycal.model.robot import Robot
from brachycal.validate import parse_name_list, parse_number_list


def add_urdf_option(parser: argparse.ArgumentParser) -> None:
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


def parse_list(text: str, name: str, kind: Callable = float, **bounds: float) -> list:
    """Values of a comma-separated option (``--points 3,4,5``), each one checked.

    ``kind`` is ``float``, ``int`` (numbers: finite, within ``low``/``high`` of ``bounds``, see
    :func:`brachycal.validate.parse_number_list`) or ``str`` (names: none empty, no repeats).
    A bad item gives a one-line error naming the option and the item.
    """
    if kind is str:
        return parse_name_list(text, name)
    return parse_number_list(text, name, kind=kind, **bounds)


def parse_numbers(text: str, name: str, count: int, **bounds: float) -> np.ndarray:
    """Exactly ``count`` finite comma-separated numbers (``--uv 540,300``), each within ``bounds``."""
    return np.array(parse_number_list(text, name, count=count, **bounds))
