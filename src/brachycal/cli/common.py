"""Options and helpers shared by the sub-commands."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable

import numpy as np
from tqdm import tqdm

from brachycal.errors import InputError
from brachycal.model.robot import Robot


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


def parse_list(text: str, name: str, kind: Callable = float) -> list:
    """Values of a comma-separated option (``--points 3,4,5``); a one-line error names the option."""
    try:
        values = [kind(x.strip()) for x in text.split(",") if x.strip()]
    except ValueError:
        raise InputError(f"{name} must be a comma-separated list, got {text!r}") from None
    if not values:
        raise InputError(f"{name} is empty")
    return values


def parse_numbers(text: str, name: str, count: int) -> np.ndarray:
    """Exactly ``count`` finite comma-separated numbers (``--uv 540,300``)."""
    values = np.array(parse_list(text, name, float))
    if values.shape != (count,) or not np.all(np.isfinite(values)):
        raise InputError(f"{name} must be {count} comma-separated finite numbers, got {text!r}")
    return values
