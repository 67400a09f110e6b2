"""The command line's option types: argparse ``type=`` converters over :mod:`brachycal.validate`'s checks.

A bad value is refused while the arguments are parsed, before any work, as
``brachycal CMD: error: argument --OPTION: <what is wrong>``: :func:`finite_float`, :func:`bounded_int`,
:func:`number_list`, :func:`name_list`, :data:`probability`, :data:`seed`, :data:`spacing_mm`,
:data:`direction`. Each one's ``rule`` attribute is the accepted range in words, for ``--help``.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from brachycal.errors import InputError
from brachycal.validate import (
    SPACING_MM_RANGE,
    check_direction,
    check_int,
    check_probability,
    check_range,
    check_seed,
    check_spacing_mm,
    interval_text,
    number_from_text,
    parse_name_list,
    parse_number_list,
    whole_from_text,
)


class OptionType:
    """An argparse ``type=``: converts and checks one option's text; ``rule`` is for ``--help``.

    A refused value raises :class:`argparse.ArgumentTypeError`, which argparse prints as one line
    naming the option (``argument --edge-mm: must be in [1, 500] mm, got 0 mm``).
    """

    def __init__(self, convert: Callable[[str], Any], rule: str, label: str) -> None:
        self.convert, self.rule, self.__name__ = convert, rule, label

    def __call__(self, text: str) -> Any:
        try:
            return self.convert(text)
        except InputError as exc:
            raise argparse.ArgumentTypeError(exc.problem) from None

    def __repr__(self) -> str:
        return f"{self.__name__}({self.rule})"


def _number(text: str, kind: type) -> float:
    """One option value: :func:`number_from_text` (or :func:`whole_from_text`) of ``text`` without blanks around."""
    value = (whole_from_text if kind is int else number_from_text)(text.strip())
    if value is None:
        raise InputError(f"must be {'a whole number' if kind is int else 'a number'}, got {text!r}")
    return value


def finite_float(
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    high_open: bool = False,
    unit: str = "",
) -> OptionType:
    """argparse type: one finite number in the range (NaN and ±inf refused)."""
    rule = interval_text(low, high, low_open, high_open, unit)

    def convert(text: str) -> float:
        return check_range(
            _number(text, float), "", low=low, high=high, low_open=low_open, high_open=high_open, unit=unit
        )

    return OptionType(convert, rule, "number")


def bounded_int(*, low: int, high: int) -> OptionType:
    """argparse type: one whole number in ``[low, high]``."""

    def convert(text: str) -> int:
        return check_int(_number(text, int), "", low=low, high=high)

    return OptionType(convert, interval_text(low, high), "whole number")


def number_list(
    *,
    count: int | None = None,
    kind: type = float,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    high_open: bool = False,
    unit: str = "",
    max_items: int = 100,
) -> OptionType:
    """argparse type: comma-separated numbers as a NumPy array (``count`` of them, or a list of 1..max)."""
    rule = (
        f"each {interval_text(low, high, low_open, high_open, unit)}"
        if (low is not None or high is not None)
        else "finite"
    )

    def convert(text: str) -> np.ndarray:
        values = parse_number_list(
            text,
            "",
            count=count,
            kind=kind,
            low=low,
            high=high,
            low_open=low_open,
            high_open=high_open,
            unit=unit,
            max_items=max_items,
        )
        return np.array(values, dtype=kind)

    return OptionType(convert, rule, "numbers")


def name_list(choices: Sequence[str] | None = None) -> OptionType:
    """argparse type: comma-separated names (a list), each among ``choices`` when given."""
    rule = f"from {', '.join(choices)}" if choices is not None else "non-empty names"
    return OptionType(lambda text: parse_name_list(text, "", choices), rule, "names")


def _probability(text: str) -> float:
    return check_probability(_number(text, float), "")


def _seed(text: str) -> int:
    return check_seed(_number(text, int), "")


def _spacing_mm(text: str) -> np.ndarray:
    values = parse_number_list(text, "", count=2)
    return check_spacing_mm(values, "")


def _direction(text: str) -> np.ndarray:
    return check_direction(parse_number_list(text, "", count=3), "")


#: argparse type: ``DX,DY,DZ`` a direction (finite, not all zero), returned as a unit ``(3,)`` array.
direction = OptionType(_direction, "finite, not all zero", "direction")
#: argparse type: a probability in [0, 1].
probability = OptionType(_probability, "in [0, 1]", "probability")
#: argparse type: a random seed, a whole number in [0, 2**32).
seed = OptionType(_seed, "in [0, 2**32)", "seed")
#: argparse type: ``SU,SV`` pixel spacing in mm/px, each plausible for ultrasound.
spacing_mm = OptionType(_spacing_mm, f"each in [{SPACING_MM_RANGE[0]:g}, {SPACING_MM_RANGE[1]:g}] mm/px", "spacing")
