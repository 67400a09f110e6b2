"""Files: atomic writes and where the bundled data lives.

Outputs are written to a temporary file in the target folder and renamed into place, so a crash
or Ctrl-C never leaves half a file; an existing file is only replaced when asked (``force``).
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from importlib import resources
from pathlib import Path
from typing import IO

from brachycal.errors import InputError


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike[str], *, force: bool = False) -> Iterator[IO[str]]:
    """Open ``path`` for writing text atomically; refuse to replace it unless ``force``."""
    path = Path(path)
    if path.exists() and not force:
        raise InputError("already exists; pass --force to replace it", file=path)
    if not path.parent.is_dir():
        raise InputError("folder does not exist", file=path.parent)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the file the usual permissions
    try:
        with os.fdopen(fd, "w", newline="") as handle:
            yield handle
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def bundled(*parts: str) -> Path:
    """Path of bundled data (``urdf/…``, ``examples/…``): in an installed wheel, or the source tree."""
    packaged = resources.files("brachycal")
    for part in parts:
        packaged = packaged.joinpath(part)
    if packaged.is_file() or packaged.is_dir():
        return Path(str(packaged))
    return Path(__file__).resolve().parents[2].joinpath(*parts)
