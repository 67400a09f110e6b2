"""The one input validator: every entry point checks its numbers and transforms here.

Each ``check_*`` function returns the value (a float, an int or a NumPy array) when it is
acceptable and raises :class:`~brachycal.errors.InputError` naming ``name`` (an option, a field, a
column) when it is not; ``file`` and ``row`` pass through to the error so that it says where the
value came from. Every comparison is written so that NaN fails it (NaN compares False), so a NaN
can never switch a check off.

The command line uses the same checks through its option types
(:mod:`brachycal.cli.option_types`): a bad value is refused while the arguments are parsed, before
any work; :func:`interval_text` states a range in words for ``--help``.

Bounds that are not physics are typo guards, chosen so that no accepted value can exhaust memory
or time: see :data:`MAX_GRID_POINTS`, :data:`MAX_TARGETS`, :data:`MAX_WORKERS`, :data:`MAX_SEEDS`.
"""

from __future__ import annotations

import math
import re
from collections.abc import Collection, Sequence
from os import PathLike

import numpy as np
from numpy.typing import ArrayLike

from brachycal.errors import InputError
from brachycal.se3 import FloatArray, rigidity_error

#: Plausible ultrasound pixel spacings, millimetres per pixel. The finest clinical images (high-
#: frequency linear probes, zoomed) are about 0.02 mm/px and the coarsest (deep abdominal sectors
#: on small screens) about 0.5 mm/px; the range leaves a factor 4 on both sides. A value 1000
#: times too small or too large (metres typed as millimetres, or the reverse) falls outside it.
SPACING_MM_RANGE = (0.005, 2.0)

#: Largest pixel coordinate accepted where the image size is not known: no ultrasound image is
#: 10000 px wide, so a larger coordinate is a typo (or metres/millimetres typed as pixels).
MAX_IMAGE_PX = 10_000

#: Grid points per cube axis: 20 gives 8000 planned poses (about an hour of planning, a day of
#: robot time); more is a typo, and 1000 per axis would be a billion poses.
MAX_GRID_POINTS = 20

#: Targets of a targeting-error evaluation (each one is two IK solves, ~10 ms): 1e5 is ~20 min.
MAX_TARGETS = 100_000

#: Local worker processes: more than any single machine's cores; each process loads the robot.
MAX_WORKERS = 256

#: Seeds (simulated sessions per setting) of a study or design comparison: each is a full
#: simulated session (seconds to minutes), so 1000 is already days of computing.
MAX_SEEDS = 1000

#: NumPy's seeds: ``SeedSequence`` takes any non-negative integer, but the twin's files and the
#: study's rows keep a seed as a 32-bit unsigned number.
SEED_LIMIT = 2**32

#: Largest coordinate (each axis) of any position brachycal reads, metres: optical and
#: electromagnetic trackers measure within a few metres of their camera or field generator, the
#: robot reaches 1.5 m from its base and a phantom is tens of centimetres across. A larger value is
#: a typo or another unit, and a value near the float limit (1e308) would overflow in the fits.
MAX_POSITION_M = 10.0

#: Longest and shortest tool (tip from its marker's or flange's origin), metres: no hand-held or
#: robot-held tool is longer than a few metres, and a tip within a few millimetres of its marker's
#: origin is not a tool. A pivot in the wrong unit lands 1000 times off: 0.4 m read as millimetres
#: is 0.4 mm, read as metres from millimetres 400 m.
TOOL_LENGTH_M_RANGE = (0.003, 3.0)

#: Largest deviation of a rotation block from orthonormality (‖RᵀR − I‖ max entry) and of its
#: determinant from 1 that a stored rigid transform may show. Transforms written with 9+ decimals
#: (every file format brachycal reads) are within 1e-6; a scaled or sheared matrix is far off.
RIGID_TOLERANCE = 1e-6


#: The text of a number as CSV and text writers write it (Python's ``repr``, ``%.17g``, the csv
#: module, ``numpy.savetxt``, C's ``printf``): ASCII digits, an optional sign, an optional decimal
#: point and an optional exponent, and nothing else. Python's ``float`` accepts more (``0_1`` is 1,
#: Arabic-Indic digits, surrounding blanks, ``infinity``), so a file's ``2_5`` would be read as 25.
DECIMAL_TEXT = r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?"
#: Non-finite numbers as those writers spell them (``nan``, ``inf``, ``-inf``; any case), which a
#: reader then refuses wherever the value must be finite.
NON_FINITE_TEXT = r"(?i:[+-]?(?:nan|inf))"
_NUMBER = re.compile(rf"(?:{DECIMAL_TEXT}|{NON_FINITE_TEXT})")
_WHOLE = re.compile(r"[+-]?[0-9]+")
# Many fields at once: each followed by a line break (which a number never holds). Possessive
# (``*+``): a greedy ``*`` keeps a backtracking point per field, some 800 bytes each (200 MB for
# the 262,144 fields of one block); the line breaks fix where each field ends, so none is needed.
_NUMBERS = re.compile(rf"(?:(?:{DECIMAL_TEXT}|{NON_FINITE_TEXT})\n)*+")


def number_from_text(text: str) -> float | None:
    """The number written as ``text`` (:data:`DECIMAL_TEXT` or ``nan``/``inf``), or None for any other text.

    No blanks around, no ``_`` digit separators, no hexadecimal, no non-ASCII digits, no ``infinity``.
    """
    return float(text) if _NUMBER.fullmatch(text) else None


def whole_from_text(text: str) -> int | None:
    """The whole number written as ``text`` (ASCII digits, an optional sign), or None for any other text."""
    return int(text) if _WHOLE.fullmatch(text) else None


def numbers_from_text(text: str) -> list[float] | None:
    """The numbers of ``text`` separated by blanks (an XML attribute's ``"1 0 0 12.5"``), each as
    :func:`number_from_text`; None if any item is not a number's text."""
    values = [number_from_text(item) for item in text.split()]
    return None if None in values else values  # type: ignore[return-value]


def wholes_from_text(text: str) -> list[int] | None:
    """The whole numbers of ``text`` separated by blanks, each as :func:`whole_from_text`; None if any is not."""
    values = [whole_from_text(item) for item in text.split()]
    return None if None in values else values  # type: ignore[return-value]


def all_number_texts(texts: Sequence[str]) -> bool:
    """Whether every text of ``texts`` is a number's (:func:`number_from_text`), checked in one regex pass."""
    return _NUMBERS.fullmatch("\n".join(texts) + "\n" if texts else "") is not None


def check_transform(
    T: ArrayLike,
    name: str,
    *,
    file: str | PathLike[str] | None = None,
    row: int | None = None,
    tolerance: float = RIGID_TOLERANCE,
) -> FloatArray:
    """A rigid transform ``(*, 4, 4)``: finite, last row ``0 0 0 1``, rotation block orthonormal with det +1.

    Args:
        T: ``(*, 4, 4)`` homogeneous transform(s), any units for the translation.
        name: what the value is (``"ProbeToTracker"``, ``"--pose"``), for the error.
        file: the file it was read from, for the error.
        row: the row it was read from, for the error.
        tolerance: largest accepted ``|RᵀR − I|`` entry and ``|det R − 1|``.

    Returns:
        ``T`` as a float array of the same shape.
    """
    A = np.asarray(T, dtype=float)
    if A.shape[-2:] != (4, 4):
        raise InputError(f"{name} must be a 4x4 matrix, got shape {A.shape}", file=file, row=row)
    if not np.all(np.isfinite(A)):
        raise InputError(f"{name} holds a non-finite value (NaN or infinity)", file=file, row=row)
    off, det, last_row = rigidity_error(A)
    if np.max(last_row, initial=0.0) > tolerance:
        raise InputError(f"{name} is not a rigid transform: its last row is not 0 0 0 1", file=file, row=row)
    bad = np.flatnonzero((off > tolerance) | (np.abs(det - 1.0) > tolerance))
    if bad.size:
        k = int(bad[0])
        which = f" (matrix {k + 1} of {off.size})" if off.ndim else ""
        raise InputError(
            f"{name}{which} is not a rigid transform: rotation block off orthonormal by "
            f"{np.ravel(off)[k]:.2g}, determinant {np.ravel(det)[k]:.6g} (scaled, sheared or mirrored)",
            file=file,
            row=row,
        )
    return A


def check_finite(
    value: ArrayLike, name: str, *, file: str | PathLike[str] | None = None, row: int | None = None
) -> FloatArray:
    """``value`` as a float array with every entry finite (no NaN, no infinity)."""
    A = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(A)):
        raise InputError(f"{name} must be finite, got {np.ravel(A).tolist()}", file=file, row=row)
    return A


def interval_text(
    low: float | None, high: float | None, low_open: bool = False, high_open: bool = False, unit: str = ""
) -> str:
    """The accepted range in words: ``in [1, 500] mm``, ``>= 0``, ``in (0, 1]``."""
    unit_text = f" {unit}" if unit else ""
    if low is not None and high is not None:
        return f"in {'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}{unit_text}"
    if low is not None:
        return f"{'>' if low_open else '>='} {low:g}{unit_text}"
    if high is not None:
        return f"{'<' if high_open else '<='} {high:g}{unit_text}"
    return "finite"


def _inside(x: float, low: float | None, high: float | None, low_open: bool, high_open: bool) -> bool:
    """Whether ``x`` is finite and within the bounds; written so that NaN is never inside."""
    if not math.isfinite(x):
        return False
    above = low is None or (x > low if low_open else x >= low)
    below = high is None or (x < high if high_open else x <= high)
    return above and below


def _where(name: str) -> str:
    return f"{name} " if name else ""


def check_range(
    value: float,
    name: str,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    high_open: bool = False,
    unit: str = "",
    file: str | PathLike[str] | None = None,
    row: int | None = None,
    column: str | None = None,
) -> float:
    """A finite number within ``[low, high]`` (open ends with ``low_open``/``high_open``); a
    refusal names ``file``, ``row`` and ``column`` when given.

    NaN and ±infinity are always refused (a NaN would otherwise pass every ``<`` test).
    """
    try:
        x = float(value)
    except OverflowError:  # an int beyond float range (10**400)
        x = math.inf
    except (TypeError, ValueError):
        raise InputError(f"{_where(name)}must be a number, got {value!r}", file=file, row=row, column=column) from None
    unit_text = f" {unit}" if unit else ""
    if not math.isfinite(x):
        raise InputError(f"{_where(name)}must be a finite number, got {x}", file=file, row=row, column=column)
    if not _inside(x, low, high, low_open, high_open):
        rule = interval_text(low, high, low_open, high_open, unit)
        raise InputError(f"{_where(name)}must be {rule}, got {x:g}{unit_text}", file=file, row=row, column=column)
    return x


def check_int(
    value: object,
    name: str,
    *,
    low: int | None = None,
    high: int | None = None,
    file: str | PathLike[str] | None = None,
    row: int | None = None,
) -> int:
    """A whole number within ``[low, high]``; ``True``/``False`` and fractional values are refused."""
    if isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)):
        n = int(value)  # exact, however large (no detour through float)
    elif isinstance(value, (float, np.floating)) and math.isfinite(value) and float(value).is_integer():
        n = int(value)
    else:
        raise InputError(f"{_where(name)}must be a whole number, got {value!r}", file=file, row=row)
    above = low is None or n >= low
    below = high is None or n <= high
    if not (above and below):
        raise InputError(f"{_where(name)}must be {interval_text(low, high)}, got {n}", file=file, row=row)
    return n


def check_positions(
    values: ArrayLike,
    name: str,
    *,
    limit: float,
    unit: str,
    file: str | PathLike[str] | None = None,
    rows: Sequence[int] | None = None,
    columns: Sequence[str] | None = None,
) -> FloatArray:
    """Coordinates ``(…, C)`` each finite and within ``±limit`` (``unit``), e.g. :data:`MAX_POSITION_M`.

    ``rows`` (one per leading index of a ``(N, C)`` table) and ``columns`` (``C`` names) place the
    first value refused; the refusal says the value is not a physical position (a typo or another unit).
    """
    A = np.asarray(values, dtype=float)
    table = A.reshape(-1, A.shape[-1]) if A.ndim else A.reshape(1, 1)
    bad = np.argwhere(~(np.abs(table) <= limit))
    if bad.size:
        k, c = (int(i) for i in bad[0])
        x = table[k, c]
        column = columns[c] if columns is not None else None
        row = rows[k] if rows is not None else None
        what = f"{_where(name)}{x:g} {unit}" if math.isfinite(x) else f"{_where(name)}{x}"
        raise InputError(
            f"{what} is beyond ±{limit:g} {unit}: not a physical position (a typo, or another unit?)",
            file=file,
            row=row,
            column=column,
        )
    return A


def check_probability(value: float, name: str, *, high: float = 1.0) -> float:
    """A probability (fraction) in ``[0, high]``."""
    return check_range(value, name, low=0.0, high=high)


def check_seed(value: object, name: str = "seed") -> int:
    """A random seed: a whole number with ``0 <= seed < 2**32``."""
    n = check_int(value, name)
    if not 0 <= n < SEED_LIMIT:
        raise InputError(f"{_where(name)}must be in [0, 2**32), got {n}")
    return n


def check_vector(
    value: ArrayLike,
    name: str,
    size: int,
    *,
    low: float | None = None,
    high: float | None = None,
    unit: str = "",
) -> FloatArray:
    """``(size,)`` finite numbers, each within ``[low, high]``."""
    try:
        A = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{_where(name)}must be {size} numbers, got {value!r}") from None
    if A.shape != (size,):
        raise InputError(f"{_where(name)}must be {size} numbers, got shape {A.shape}")
    for k, x in enumerate(A):
        check_range(x, f"{name} value {k + 1}".strip() if size > 1 else name, low=low, high=high, unit=unit)
    return A


def check_direction(value: ArrayLike, name: str) -> FloatArray:
    """A direction: ``(3,)`` finite numbers, not all zero; returned normalised (unit length).

    Any scale works (1,0,0 or 1e-12,0,0 or 1e300,0,0: the vector is first divided by its largest
    component, so its norm neither underflows nor overflows); only the zero vector has no direction.
    """
    v = check_vector(value, name, 3)
    largest = float(np.abs(v).max())
    if not largest > 0:
        raise InputError(f"{_where(name)}is the zero vector; a direction needs a non-zero component")
    v = v / largest
    return v / np.linalg.norm(v)


def _spacing_problem(value: float, unit: str) -> str | None:
    """Why ``value`` (in ``unit``: ``"mm"`` or ``"m"`` per pixel) is not a plausible spacing, or None.

    A value a thousand times off in the direction of a unit slip gets the hint: in millimetres,
    1.9e-4 is a spacing in metres; in metres, 0.19 is a spacing in millimetres.
    """
    scale = 1.0 if unit == "mm" else 1e-3  # accepted range in the unit given
    low, high = SPACING_MM_RANGE[0] * scale, SPACING_MM_RANGE[1] * scale
    if not math.isfinite(value):
        return f"must be a finite number of {unit}/px, got {value}"
    if value <= 0:
        return f"must be positive, got {value:g} {unit}/px"
    if low <= value <= high:
        return None
    if unit == "mm" and low <= value * 1e3 <= high:
        return (
            f"{value:g} mm/px is far below any ultrasound image's ({low:g}..{high:g} mm/px): it looks like a "
            f"spacing in metres typed as millimetres; give {value * 1e3:g}"
        )
    if unit == "m" and low <= value * 1e-3 <= high:
        return (
            f"{value:g} m/px is far above any ultrasound image's ({low:g}..{high:g} m/px): it looks like a "
            f"spacing in millimetres given as metres; give {value * 1e-3:g}"
        )
    return f"must be in [{low:g}, {high:g}] {unit}/px (a plausible ultrasound pixel spacing), got {value:g}"


def _check_spacing(
    value: ArrayLike, name: str, unit: str, file: str | PathLike[str] | None, column: str | None
) -> FloatArray:
    try:
        A = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(
            f"{_where(name)}must be two numbers (s_u, s_v), got {value!r}", file=file, column=column
        ) from None
    if A.shape != (2,):
        raise InputError(f"{_where(name)}must be two numbers (s_u, s_v), got shape {A.shape}", file=file, column=column)
    for axis, x in zip("uv", A, strict=True):
        problem = _spacing_problem(float(x), unit)
        if problem:
            raise InputError(f"{_where(name)}s_{axis} {problem}", file=file, column=column)
    return A


def check_spacing_mm(
    value: ArrayLike, name: str, *, file: str | PathLike[str] | None = None, column: str | None = None
) -> FloatArray:
    """Pixel spacing ``(s_u, s_v)`` in millimetres per pixel: finite, within :data:`SPACING_MM_RANGE`.

    A value a thousand times too small is named as a spacing in metres typed as millimetres.
    """
    return _check_spacing(value, name, "mm", file, column)


def check_spacing_m(
    value: ArrayLike, name: str, *, file: str | PathLike[str] | None = None, column: str | None = None
) -> FloatArray:
    """Pixel spacing ``(s_u, s_v)`` in metres per pixel (the library's unit), ``(2,)``.

    Finite and within :data:`SPACING_MM_RANGE` (converted to metres); a value a thousand times
    too large (0.19 for 0.19 mm/px) is named as millimetres given as metres.
    """
    return _check_spacing(value, name, "m", file, column)


def check_pixel(uv_px: ArrayLike, name: str, *, size_px: ArrayLike | None = None) -> FloatArray:
    """Pixel(s) ``(2,)`` or ``(N, 2)`` ``(u, v)`` inside the image.

    The image covers ``-0.5 <= u <= width - 0.5`` and ``-0.5 <= v <= height - 0.5``: pixel
    ``(0, 0)``'s centre is the origin and each pixel extends half a pixel around its centre (the
    session reader accepts annotations on the same range). Without ``size_px`` (width, height) the
    bound is :data:`MAX_IMAGE_PX`.
    """
    uv = np.asarray(uv_px, dtype=float)
    if uv.shape[-1:] != (2,) or uv.ndim > 2:
        raise InputError(f"{_where(name)}must be (u, v) pixel pairs, got shape {uv.shape}")
    if size_px is None:
        upper = np.array([MAX_IMAGE_PX, MAX_IMAGE_PX], dtype=float)
        image = "any ultrasound image"
    else:
        size = np.asarray(size_px, dtype=float)
        upper = size - 0.5
        image = f"the {size[0]:g} x {size[1]:g} px image"
    for k, pair in enumerate(np.atleast_2d(uv)):
        which = f" (pixel {k + 1})" if uv.ndim == 2 else ""
        for axis, x, hi in zip("uv", pair, upper, strict=True):
            if not math.isfinite(x):
                raise InputError(f"{_where(name)}{axis} must be a finite number, got {x}{which}")
            if not -0.5 <= x <= hi:
                raise InputError(
                    f"{_where(name)}{axis} = {x:g} px is outside {image}{which} (-0.5 <= {axis} <= {hi:g})"
                )
    return uv


# ---------------------------------------------------------------------------------------------
# Comma-separated lists (``--centre-mm 800,100,1050``)


def parse_number_list(
    text: str,
    name: str,
    *,
    count: int | None = None,
    kind: type = float,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    high_open: bool = False,
    unit: str = "",
    max_items: int = 100,
) -> list:
    """Comma-separated numbers, each one checked: a typo in any item names that item.

    Args:
        text: ``"3,4,5"``; blanks around items are allowed, empty items are not.
        name: the option, for the error.
        count: exact number of items required (None: 1 to ``max_items``).
        kind: ``float`` or ``int`` (whole numbers).
        low: range of each item, as :func:`check_range`.
        high: as ``low``.
        low_open: as ``low``.
        high_open: as ``low``.
        unit: as ``low``.
    """
    items = [item.strip() for item in str(text).split(",")]
    if count is not None and len(items) != count:
        raise InputError(f"{_where(name)}must be {count} comma-separated numbers, got {len(items)} in {text!r}")
    if len(items) > max_items:
        raise InputError(f"{_where(name)}takes at most {max_items} values, got {len(items)}")
    values: list[int | float] = []
    for k, item in enumerate(items, start=1):
        label = f"{name} value {k}".strip() if len(items) > 1 else name
        if not item:
            raise InputError(f"{_where(label)}is empty (in {text!r})")
        number = (whole_from_text if kind is int else number_from_text)(item)
        if number is None:
            what = "a whole number" if kind is int else "a number"
            raise InputError(f"{_where(label)}must be {what}, got {item!r}")
        if kind is int:
            values.append(check_int(number, label, low=low, high=high))  # type: ignore[arg-type]
        else:
            values.append(
                check_range(number, label, low=low, high=high, low_open=low_open, high_open=high_open, unit=unit)
            )
    return values


def check_token(
    name: str,
    what: str,
    *,
    file: str | PathLike[str] | None = None,
    row: int | None = None,
    column: str | None = None,
) -> str:
    """``name`` (a sample's, a point's) if it is a plain token: non-empty, printable, no blank, comma
    or quote, so that it is written into a CSV field as it is and read back the same."""
    if not name or not name.isprintable() or any(c.isspace() or c in ",\"'" for c in name):
        raise InputError(
            f"{what} name {name!r} is not a plain token (no blank, comma, quote or control character)",
            file=file,
            row=row,
            column=column,
        )
    return name


def parse_name_list(text: str, name: str, choices: Collection[str] | None = None) -> list[str]:
    """Comma-separated names, none empty, no repeats, each among ``choices`` when given."""
    items = [item.strip() for item in str(text).split(",")]
    seen: set[str] = set()
    for k, item in enumerate(items, start=1):
        if not item:
            raise InputError(f"{_where(name)}item {k} is empty (in {text!r})")
        if choices is not None and item not in choices:
            raise InputError(f"{_where(name)}{item!r} is not one of: {', '.join(choices)}")
        if item in seen:
            raise InputError(f"{_where(name)}names {item!r} twice")
        seen.add(item)
    return items
