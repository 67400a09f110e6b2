"""One check for every result file brachycal reads back: a declarative schema of small Python
checks (:data:`Spec`) run on the parsed JSON document before anything in it is used.

Each format keeps its own schema beside its writer (``brachycal-result/1``, ``brachycal-nwire/1``,
``brachycal-stepper/1``, ``brachycal-pivot/1``) and reads its files with :func:`read_document`; the
building blocks here check types and shapes, and the numbers with :mod:`brachycal.validate`'s own
functions: finite values, proper rotations, pixel spacings, and the plausible magnitudes below. A
problem is refused in one line naming the file and the key's place in the document
(``models.rigid.image_to_probe_mm``).

Design: ``docs/design/files.md``, "The result file's schema".
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from brachycal.data.json_files import check_json_tree, json_place, read_json, shown
from brachycal.errors import InputError
from brachycal.validate import (
    MAX_IMAGE_PX,
    SPACING_MM_RANGE,
    check_int,
    check_range,
    check_spacing_mm,
    check_transform,
)

#: Largest translation of a stored transform or position, metres: tools, images, phantoms and
#: joint origins are within a metre of their parent frames (the SDA10F's arms reach 0.7 m, a
#: tracker sees a few metres); 5 m is no robot cell's or tracker's, and a length in millimetres
#: given as metres (x 1000) is refused.
MAX_TRANSLATION_M = 5.0

#: Largest number of samples, folds or replicates a result counts (a day at the robot is ~1e4 poses).
MAX_COUNT = 10**7

#: Largest departure from a right angle between the columns of an Image -> Probe matrix (degrees):
#: an affine fit on PLUS's own stepper recordings is 1.5 degrees off square pixels; a scanner's
#: pixels are not sheared by more than 5 degrees, and a corrupted element is.
MAX_SKEW_DEG = 5.0


@dataclass(frozen=True)
class Where:
    """The file being checked and a place inside its document."""

    file: str | os.PathLike[str] | None
    place: str

    def at(self, key: str | int) -> Where:
        return Where(self.file, json_place(self.place, key))

    def refuse(self, problem: str) -> InputError:
        return InputError(problem, file=self.file, column=self.place or None)


#: A check of one value at a place: returns nothing, raises :class:`InputError` naming the place.
Spec = Callable[[Any, Where], None]


def _kind(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true/false"
    if isinstance(value, int | float):
        return "a number"
    if isinstance(value, str):
        return "a string"
    return "a list" if isinstance(value, list) else "an object" if isinstance(value, dict) else type(value).__name__


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


# ---------------------------------------------------------------------------------------------
# The building blocks


def number(low: float | None = None, high: float | None = None, unit: str = "", *, low_open: bool = False) -> Spec:
    """A finite JSON number within ``[low, high]`` (:func:`~brachycal.validate.check_range`)."""

    def check(value: Any, where: Where) -> None:
        if not _is_number(value):
            raise where.refuse(f"must be a number, got {_kind(value)}")
        try:
            check_range(value, "", low=low, high=high, low_open=low_open, unit=unit)
        except InputError as exc:
            raise where.refuse(exc.problem) from None

    return check


def integer(low: int = 0, high: int = MAX_COUNT) -> Spec:
    """A whole JSON number within ``[low, high]`` (:func:`~brachycal.validate.check_int`)."""

    def check(value: Any, where: Where) -> None:
        if not _is_number(value):
            raise where.refuse(f"must be a whole number, got {_kind(value)}")
        try:
            check_int(value, "", low=low, high=high)
        except InputError as exc:
            raise where.refuse(exc.problem) from None

    return check


def text(*, nonempty: bool = False) -> Spec:
    """A JSON string (not empty with ``nonempty``)."""

    def check(value: Any, where: Where) -> None:
        what = "a non-empty string" if nonempty else "a string"
        if not isinstance(value, str):
            raise where.refuse(f"must be {what}, got {_kind(value)}")
        if nonempty and not value:
            raise where.refuse(f"must be {what}, got an empty one")

    return check


def one_of(choices: tuple[str, ...]) -> Spec:
    """A JSON string among ``choices``."""

    def check(value: Any, where: Where) -> None:
        if value not in choices:
            raise where.refuse(f"must be one of {', '.join(choices)}, got {shown(value)}")

    return check


def nullable(spec: Spec) -> Spec:
    """``null`` or what ``spec`` accepts."""

    def check(value: Any, where: Where) -> None:
        if value is not None:
            spec(value, where)

    return check


def array(item: Spec, *, length: int | None = None, nonempty: bool = False) -> Spec:
    """A JSON list whose every item ``item`` accepts (of ``length`` items when given)."""

    def check(value: Any, where: Where) -> None:
        if not isinstance(value, list):
            raise where.refuse(f"must be a list, got {_kind(value)}")
        if length is not None and len(value) != length:
            raise where.refuse(f"must hold {length} values, got {len(value)}")
        if nonempty and not value:
            raise where.refuse("must not be empty")
        for k, entry in enumerate(value):
            item(entry, where.at(k))

    return check


def mapping(value: Spec, *, keys: tuple[str, ...] | None = None, nonempty: bool = False) -> Spec:
    """A JSON object of names (each among ``keys`` when given) to values ``value`` accepts."""

    def check(raw: Any, where: Where) -> None:
        if not isinstance(raw, dict):
            raise where.refuse(f"must be an object (name: value), got {_kind(raw)}")
        if nonempty and not raw:
            raise where.refuse("must not be empty")
        for key, entry in raw.items():
            if not key or (keys is not None and key not in keys):
                known = f" (known: {', '.join(keys)})" if keys is not None else ""
                raise where.refuse(f"unknown name {shown(key)}{known}")
            value(entry, where.at(key))

    return check


@dataclass(frozen=True)
class Obj:
    """A JSON object with the ``required`` and ``optional`` keys (others are accepted unchecked,
    unless ``closed``)."""

    required: Mapping[str, Spec] = field(default_factory=dict)
    optional: Mapping[str, Spec] = field(default_factory=dict)
    closed: bool = False

    def __call__(self, raw: Any, where: Where) -> None:
        if not isinstance(raw, dict):
            raise where.refuse(f"must be an object, got {_kind(raw)}")
        for key, spec in self.required.items():
            if key not in raw:
                raise where.at(key).refuse("missing")
            spec(raw[key], where.at(key))
        for key, spec in self.optional.items():
            if key in raw:
                spec(raw[key], where.at(key))
        if self.closed:
            extra = sorted(set(raw) - set(self.required) - set(self.optional))
            if extra:
                raise where.refuse(
                    f"unknown key {shown(extra[0])} (it holds {', '.join([*self.required, *self.optional])})"
                )


def transform(value: Any, where: Where) -> None:
    """A rigid 4x4 transform (rows of numbers, metres): finite, last row 0 0 0 1, a proper rotation
    (:func:`~brachycal.validate.check_transform`), its translation within :data:`MAX_TRANSLATION_M`."""
    array(array(number(), length=4), length=4)(value, where)
    try:
        T = check_transform(np.array(value, dtype=float), "4x4 matrix")
    except InputError as exc:
        raise where.refuse(exc.problem) from None
    reach = float(np.max(np.abs(T[:3, 3])))
    if reach > MAX_TRANSLATION_M:
        raise where.refuse(
            f"translation of {reach:g} m: beyond {MAX_TRANSLATION_M:g} m from its parent frame "
            "(millimetres given as metres?)"
        )


def spacing(value: Any, where: Where) -> None:
    """A pixel spacing ``[s_u, s_v]``, mm/px (:func:`~brachycal.validate.check_spacing_mm`)."""
    array(number(), length=2)(value, where)
    check_spacing_mm(value, "", file=where.file, column=where.place)


def image_size(value: Any, where: Where) -> None:
    """``[width, height]``: whole pixels in ``[1, MAX_IMAGE_PX]``."""
    try:
        array(integer(1, MAX_IMAGE_PX), length=2)(value, where)
    except InputError:
        raise where.refuse(
            f"must be two whole numbers of pixels in [1, {MAX_IMAGE_PX}] (width, height), got {shown(value)}"
        ) from None


def image_to_probe_mm(value: Any, where: Where) -> None:
    """PLUS's Image -> Probe ``(4, 4)``, pixels -> millimetres: finite, last row ``0 0 0 1``,
    columns ``u`` and ``v`` (and the normal's) of a plausible pixel spacing
    (:data:`~brachycal.validate.SPACING_MM_RANGE`), at right angles within :data:`MAX_SKEW_DEG`,
    right-handed, the translation within :data:`MAX_TRANSLATION_M`."""
    array(array(number(), length=4), length=4)(value, where)
    M = np.array(value, dtype=float)
    if not np.allclose(M[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        raise where.refuse(f"last row must be 0 0 0 1, got {shown(M[3].tolist())}")
    lengths = np.linalg.norm(M[:3, :3], axis=0)
    low, high = SPACING_MM_RANGE
    for name, length in zip(("u", "v", "normal"), lengths, strict=True):
        if not low <= length <= high:
            raise where.refuse(
                f"its {name} column is {length:g} mm per pixel long: not a pixel spacing in [{low:g}, {high:g}] "
                "(a corrupted or sheared matrix?)"
            )
    U = M[:3, :3] / lengths
    cosines = np.abs(U.T @ U - np.eye(3))
    worst = float(np.degrees(np.arcsin(min(1.0, float(cosines.max())))))
    if worst > MAX_SKEW_DEG:
        raise where.refuse(
            f"its columns are {worst:.3g} degrees off a right angle (at most {MAX_SKEW_DEG:g}): a sheared matrix"
        )
    if np.linalg.det(U) <= 0.0:
        raise where.refuse("its columns are left-handed (an improper rotation: a mirrored image?)")
    reach = float(np.max(np.abs(M[:3, 3]))) * 1e-3
    if reach > MAX_TRANSLATION_M:
        raise where.refuse(f"translation of {reach * 1e3:g} mm: beyond {MAX_TRANSLATION_M:g} m from the probe")


def validate_document(
    doc: Any, path: str | os.PathLike[str] | None, expected_format: str, schema: Spec
) -> dict[str, Any]:
    """``doc`` (a parsed JSON document) if it is an object of ``expected_format`` that ``schema``
    accepts, and every value anywhere is finite.

    Raises:
        InputError: the first problem, naming ``path`` and the place in the document.
    """
    check_json_tree(doc, path)
    top = Where(path, "")
    if not isinstance(doc, dict) or doc.get("format") != expected_format:
        found = doc.get("format") if isinstance(doc, dict) else None
        raise InputError(f"format is {shown(found)}, expected {expected_format!r}", file=path, key="format")
    schema(doc, top)
    return doc


def read_document(path: str | os.PathLike[str], expected_format: str, schema: Spec) -> dict[str, Any]:
    """The JSON object in ``path``, bounded (:func:`~brachycal.data.json_files.read_json`), of
    ``expected_format`` and accepted by ``schema`` (:func:`validate_document`).

    Raises:
        InputError: the file cannot be read, is not a regular file, too large, not JSON, of another
            format, or the first value the schema refuses (naming the file and the key).
    """
    path = Path(path)
    return validate_document(read_json(path), path, expected_format, schema)
