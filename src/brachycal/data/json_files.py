"""brachycal's own JSON files read back: one reader for every ``brachycal-*/N`` format.

Result files (``brachycal-result/1``, ``-pivot/1``, ``-nwire/1``) and the twin's truth
(``brachycal-truth/1``) are JSON objects whose ``format`` key names their format and version;
:func:`read_format_json` reads one and refuses anything else with one line naming the file.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from brachycal.errors import InputError
from brachycal.inputs import MAX_DOCUMENT_BYTES, read_input_text


def read_json(path: str | os.PathLike[str]) -> Any:
    """The JSON value in ``path``.

    Raises:
        InputError: the file cannot be read or is not valid JSON (or not UTF-8), naming the file.
    """
    try:
        return json.loads(read_input_text(path, max_bytes=MAX_DOCUMENT_BYTES))
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror})", file=path) from None
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as exc:
        raise InputError(f"not valid JSON ({exc})", file=path) from None


def read_format_json(path: str | os.PathLike[str], expected_format: str) -> dict[str, Any]:
    """The JSON object in ``path`` whose ``format`` is ``expected_format``.

    Raises:
        InputError: the file cannot be read, is not valid JSON (or not UTF-8), is not a JSON
            object, or is of another format (naming the file, and the ``format`` key).
    """
    path = Path(path)
    raw = read_json(path)
    if not isinstance(raw, dict) or raw.get("format") != expected_format:
        found = raw.get("format") if isinstance(raw, dict) else None
        raise InputError(f"format is {found!r}, expected {expected_format!r}", file=path, column="format")
    return raw
