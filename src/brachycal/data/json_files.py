"""brachycal's own JSON files read back: one reader for every ``brachycal-*/N`` format.

Result files (``brachycal-result/1``, ``-pivot/1``, ``-nwire/1``) and the twin's truth
(``brachycal-truth/1``) are JSON objects whose ``format`` key names their format and version;
:func:`read_format_json` reads one and refuses anything else with one line naming the file.

The reader bounds what it holds, so that no file can exhaust memory or time or hand a reader a
value no check expects: it reads regular files only (not a folder, a FIFO or a device), at most
:data:`MAX_JSON_BYTES`, nested at most :data:`MAX_JSON_DEPTH` deep, with integers of at most
:data:`MAX_JSON_INT_DIGITS` digits and finite numbers only (``NaN``, ``Infinity`` and ``1e400``,
which Python's ``json`` accepts, are refused naming their place: ``spacing_mm.kabsch[0]``).
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

from brachycal.errors import InputError
from brachycal.inputs import MAX_DOCUMENT_BYTES, read_input_bytes

#: Largest JSON file read, bytes: brachycal's largest (a whole-chain result with the robot
#: identified and its per-pixel map) is under 1 MB; the documents' cap leaves room for any
#: session's size and stops a wrong file (an image, a log) before it fills memory.
MAX_JSON_BYTES = MAX_DOCUMENT_BYTES

#: Deepest nesting of objects and arrays: brachycal's files nest at most 7 deep; Python's
#: ``json`` would recurse until the interpreter's limit (a ``RecursionError``) on deeper ones.
MAX_JSON_DEPTH = 64

#: Most digits of an integer: no count, size or seed in brachycal's files has more than 10;
#: longer ones are typos or attacks (Python refuses to convert more than 4300 digits at all).
MAX_JSON_INT_DIGITS = 20
_INT_LIMIT = 10**MAX_JSON_INT_DIGITS


class _Refused:
    """A number the parser met that the reader refuses (``NaN``, ``Infinity``, ``1e400``, a huge
    integer): kept in place so that the refusal can name where it is."""

    def __init__(self, text: str, why: str) -> None:
        self.text, self.why = text, why


def _constant(text: str) -> _Refused:
    return _Refused(text, "is not a finite number (JSON numbers must be finite)")


def _float(text: str) -> float | _Refused:
    value = float(text)
    return value if math.isfinite(value) else _Refused(text, "is not a finite number (beyond floating point range)")


def _int(text: str) -> int | _Refused:
    digits = len(text.lstrip("-"))
    if digits > MAX_JSON_INT_DIGITS:
        return _Refused(f"{text[:12]}...", f"is an integer of {digits} digits (at most {MAX_JSON_INT_DIGITS})")
    return int(text)


def json_place(parent: str, key: str | int) -> str:
    """The place of ``key`` inside ``parent`` as the refusals name it: ``a.b``, ``a.b[2]`` (a key
    longer than 40 characters cut, so that the refusal stays one readable line)."""
    if isinstance(key, int):
        return f"{parent}[{key}]"
    name = key if len(key) <= 40 else f"{key[:37]}..."
    return f"{parent}.{name}" if parent else name


def shown(value: Any) -> str:
    """``repr(value)`` cut to 80 characters, for a refusal."""
    text = repr(value)
    return text if len(text) <= 80 else f"{text[:77]}..."


def check_json_tree(value: Any, file: str | os.PathLike[str] | None = None, *, place: str = "") -> None:
    """Refuse a JSON value nested deeper than :data:`MAX_JSON_DEPTH` or holding a non-finite
    number, an integer of more than :data:`MAX_JSON_INT_DIGITS` digits, or a value that is not
    JSON's (naming the first such place, e.g. ``column 'loocv.icp.errors_mm[3]'``).

    Walks iteratively (no recursion, whatever the depth).
    """
    stack: list[tuple[Any, str, int]] = [(value, place, 0)]
    while stack:
        node, where, depth = stack.pop()
        if depth > MAX_JSON_DEPTH:
            cut = where if len(where) < 80 else f"{where[:60]}..."
            raise InputError(f"nested more than {MAX_JSON_DEPTH} deep", file=file, column=cut or None)
        if isinstance(node, dict):
            for key, item in reversed(node.items()):
                if not isinstance(key, str):
                    raise InputError(f"key {shown(key)} is not a string", file=file, column=where or None)
                stack.append((item, json_place(where, key), depth + 1))
        elif isinstance(node, list):
            if all(type(item) is float for item in node) and math.isfinite(sum(node)):
                continue  # numbers only, all finite (a sum of finite floats that overflows is checked below)
            stack.extend((item, json_place(where, k), depth + 1) for k, item in reversed(list(enumerate(node))))
        elif isinstance(node, _Refused):
            raise InputError(f"{node.text} {node.why}", file=file, column=where or None)
        elif isinstance(node, float):
            if not math.isfinite(node):
                raise InputError(f"{node} is not a finite number", file=file, column=where or None)
        elif isinstance(node, bool) or node is None or isinstance(node, str):
            pass
        elif isinstance(node, int):
            if abs(node) >= _INT_LIMIT:
                raise InputError(
                    f"is an integer of more than {MAX_JSON_INT_DIGITS} digits", file=file, column=where or None
                )
        else:
            raise InputError(f"{type(node).__name__} is not a JSON value", file=file, column=where or None)


def read_json_bytes(path: str | os.PathLike[str]) -> bytes:
    """The bytes of the JSON file ``path``: a regular file of at most :data:`MAX_JSON_BYTES`
    (:func:`~brachycal.inputs.read_input_bytes`), without a UTF-8 byte-order mark.

    Raises:
        InputError: the file cannot be read, is not a regular file (a folder, a FIFO, a device) or
            is larger than :data:`MAX_JSON_BYTES`, naming the file.
    """
    data = read_input_bytes(path, max_bytes=MAX_JSON_BYTES)
    return data.removeprefix(b"\xef\xbb\xbf")


def parse_json(data: bytes, path: str | os.PathLike[str]) -> Any:
    """The JSON value in ``data`` (the bytes of the file ``path``), bounded (module docstring).

    Raises:
        InputError: not valid JSON (or not UTF-8), nested too deeply, or holding a non-finite number
            or a huge integer (naming the file, and the place in it).
    """
    try:
        value = json.loads(data.decode("utf-8"), parse_constant=_constant, parse_float=_float, parse_int=_int)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"not valid JSON ({exc})", file=path) from None
    except RecursionError:
        raise InputError(f"not valid JSON: nested more than {MAX_JSON_DEPTH} deep", file=path) from None
    except ValueError as exc:  # any conversion the hooks above did not foresee
        raise InputError(f"not valid JSON ({exc})", file=path) from None
    check_json_tree(value, path)
    return value


def read_json(path: str | os.PathLike[str]) -> Any:
    """The JSON value in ``path``: :func:`read_json_bytes` then :func:`parse_json`.

    Raises:
        InputError: the file cannot be read, is not a regular file, is larger than
            :data:`MAX_JSON_BYTES`, is not valid JSON (or not UTF-8), is nested too deeply, or
            holds a non-finite number or a huge integer (naming the file, and the place in it).
    """
    return parse_json(read_json_bytes(path), path)


def read_format_json(path: str | os.PathLike[str], expected_format: str) -> dict[str, Any]:
    """The JSON object in ``path`` whose ``format`` is ``expected_format`` (read by :func:`read_json`).

    Raises:
        InputError: the file cannot be read, is not valid JSON (or not UTF-8), is not a JSON
            object, or is of another format (naming the file, and the ``format`` key).
    """
    path = Path(path)
    raw = read_json(path)
    if not isinstance(raw, dict) or raw.get("format") != expected_format:
        found = raw.get("format") if isinstance(raw, dict) else None
        raise InputError(f"format is {shown(found)}, expected {expected_format!r}", file=path, key="format")
    return raw
