"""Inputs: every file a command reads is checked before it is read, and read with a bound.

One way in for every reader of brachycal (:func:`open_input`, :func:`read_input_bytes`,
:func:`read_input_text`; :func:`check_input_file` where a library opens the file itself):

- **A regular file, or refused in one line.** A folder, a device (``/dev/zero``), a FIFO (named
  pipe) or a socket given as an input file is refused when it is opened, naming it: such a file
  has no end, or none that can be known before reading it all. A symlink to a regular file is
  fine. The check is made on the opened descriptor (opened without blocking, so that opening a
  FIFO cannot hang), so a file swapped between a check and the read is still caught.
- **At most so many bytes.** A file read whole into memory has a cap by kind (the ``MAX_*``
  constants below: documents such as JSON, TOML and XML; CSV tables; meshes), checked against
  its size before reading and again while reading (a file that grows meanwhile). Files that are
  read in blocks (joint logs, bags, MetaImage pixel data) have no cap on their size; their
  readers hold one block at a time.
- **Recorded.** While the command line runs a command (:func:`recording_inputs`), every input
  file opened is recorded (device and inode), so that an output can never be one of the
  command's inputs: :class:`~brachycal.io.OutputSet` refuses to claim or replace one
  (:func:`input_at`), ``--force`` or not.
"""

from __future__ import annotations

import contextlib
import io
import os
import stat
import threading
from collections.abc import Callable, Iterator
from typing import IO, Literal, overload

from brachycal.errors import InputError

__all__ = [
    "MAX_DOCUMENT_BYTES",
    "MAX_MESH_BYTES",
    "MAX_TABLE_BYTES",
    "check_input_file",
    "check_memory",
    "file_kind",
    "hash_input",
    "input_at",
    "open_input",
    "read_input_bytes",
    "read_input_text",
    "recording_inputs",
]

MiB = 1 << 20

#: Documents read whole and parsed as a tree: JSON result files, TOML descriptions and sessions,
#: XML (URDF, SRDF, PLUS configurations and segmented frames). Ours are kilobytes to a few MB.
MAX_DOCUMENT_BYTES = 64 * MiB

#: CSV tables read whole (marks, images, poses, plans, a session's files, configurations of
#: ``verify``): each field becomes a Python string, so a table holds ~10 times its size in memory.
MAX_TABLE_BYTES = 64 * MiB

#: Mesh files of a robot description, copied into exports and the 3D view.
MAX_MESH_BYTES = 256 * MiB

_lock = threading.Lock()
_recordings: list[dict[tuple[int, int], str]] = []


def file_kind(mode: int) -> str:
    """What a file is, from its ``st_mode``: ``"a folder"``, ``"a device"``, ``"a FIFO (named pipe)"``,
    ``"a socket"``, ``"a regular file"``."""
    if stat.S_ISREG(mode):
        return "a regular file"
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def _megabytes(n: int) -> str:
    return f"{n / MiB:.3g} MB" if n >= MiB else f"{n} bytes"


def _check_stat(path: str | os.PathLike[str], st: os.stat_result, max_bytes: int | None, folder_ok: bool) -> None:
    if stat.S_ISDIR(st.st_mode) and folder_ok:
        return
    if not stat.S_ISREG(st.st_mode):
        kind = file_kind(st.st_mode)
        if kind == "a folder":
            raise InputError("is a folder; expected a file", file=path)
        raise InputError(f"is {kind}, not a regular file; an input must be a regular file", file=path)
    if max_bytes is not None and st.st_size > max_bytes:
        raise InputError(
            f"is larger than {_megabytes(max_bytes)} ({st.st_size} bytes), the most brachycal reads of a file "
            "of this kind: is it the file meant?",
            file=path,
        )
    _record(path, st)


def _record(path: str | os.PathLike[str], st: os.stat_result) -> None:
    with _lock:
        for record in _recordings:
            record.setdefault((st.st_dev, st.st_ino), str(path))


def _os_error(path: str | os.PathLike[str], exc: OSError) -> InputError:
    if isinstance(exc, FileNotFoundError):
        return InputError("no such file", file=path)
    if isinstance(exc, NotADirectoryError):
        return InputError("no such file (a folder on its path is a file)", file=path)
    return InputError(f"cannot read ({exc.strerror or exc})", file=path)


def check_input_file(
    path: str | os.PathLike[str], *, max_bytes: int | None = None, folder_ok: bool = False
) -> os.stat_result:
    """Check that ``path`` is a regular file (following symlinks) of at most ``max_bytes``; record it.

    For inputs that a library opens by name (a ROS bag, a mesh copied by path). ``folder_ok``:
    a folder is accepted too (a ROS 2 bag, a session).

    Raises:
        InputError: missing, unreadable, a folder (unless ``folder_ok``), a device, FIFO or socket,
            or larger than ``max_bytes`` — naming the file.
    """
    try:
        st = os.stat(path)
    except OSError as exc:
        raise _os_error(path, exc) from None
    _check_stat(path, st, max_bytes, folder_ok)
    return st


@overload
def open_input(
    path: str | os.PathLike[str], mode: Literal["rb"] = "rb", *, max_bytes: int | None = None
) -> IO[bytes]: ...
@overload
def open_input(
    path: str | os.PathLike[str], mode: Literal["r"], *, max_bytes: int | None = None, encoding: str = "utf-8"
) -> IO[str]: ...
def open_input(
    path: str | os.PathLike[str], mode: str = "rb", *, max_bytes: int | None = None, encoding: str = "utf-8"
) -> IO[bytes] | IO[str]:
    """Open the regular file ``path`` for reading (``"rb"``, or ``"r"``: text with ``newline=""``).

    The file is opened without blocking and checked on its descriptor (:func:`check_input_file`'s
    rules), so a FIFO or device is refused without waiting for a writer. ``max_bytes`` caps the
    size at opening; a reader that holds the whole file uses :func:`read_input_bytes` instead.

    Raises:
        InputError: naming the file (see :func:`check_input_file`).
    """
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags)
    except OSError as exc:
        with contextlib.suppress(OSError):  # a socket cannot be opened: say what it is
            _check_stat(path, os.stat(path), None, folder_ok=False)
        raise _os_error(path, exc) from None
    try:
        _check_stat(path, os.fstat(fd), max_bytes, folder_ok=False)
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        binary = os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise
    if mode == "rb":
        return binary
    if mode == "r":
        return io.TextIOWrapper(binary, encoding=encoding, newline="")
    binary.close()
    raise ValueError(f"mode {mode!r}: an input is opened 'rb' or 'r'")


def read_input_bytes(path: str | os.PathLike[str], *, max_bytes: int) -> bytes:
    """The bytes of the regular file ``path``, at most ``max_bytes`` (checked before and while reading).

    Raises:
        InputError: naming the file (see :func:`check_input_file`), or it grew past ``max_bytes``.
    """
    with open_input(path, max_bytes=max_bytes) as handle:
        data = handle.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise InputError(
            f"is larger than {_megabytes(max_bytes)}, the most brachycal reads of a file of this kind "
            "(it grew while read)",
            file=path,
        )
    return data


def read_input_text(path: str | os.PathLike[str], *, max_bytes: int, encoding: str = "utf-8") -> str:
    """The text of the regular file ``path`` (:func:`read_input_bytes`), decoded; a UTF-8 byte-order
    mark at its start is dropped. Raises ``UnicodeDecodeError`` for the caller to name its format."""
    data = read_input_bytes(path, max_bytes=max_bytes)
    if encoding.replace("-", "").lower() == "utf8":
        encoding = "utf-8-sig"
    return data.decode(encoding)


def memory_bytes() -> int | None:
    """The machine's physical memory in bytes, or ``None`` where the system does not say."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):  # pragma: no cover - not POSIX
        return None


def check_memory(nbytes: int, what: str, *, file: str | os.PathLike[str]) -> None:
    """Refuse to allocate ``nbytes`` for ``what`` (announced by ``file``'s header) if that is more
    than half the machine's memory: a size read from a file is checked before it is allocated.

    Raises:
        InputError: naming the file, the size and the machine's memory.
    """
    total = memory_bytes()
    if total is not None and nbytes > total // 2:
        raise InputError(
            f"{what} would take {_megabytes(nbytes)}, more than half of this machine's {_megabytes(total)} of memory",
            file=file,
        )


# --- which inputs a command read ------------------------------------------------------------------
@contextlib.contextmanager
def recording_inputs() -> Iterator[dict[tuple[int, int], str]]:
    """Record every input file opened in the block (any thread): ``(st_dev, st_ino) → path``.

    The command line runs each command inside one, so that its outputs are never its inputs.
    """
    record: dict[tuple[int, int], str] = {}
    with _lock:
        _recordings.append(record)
    try:
        yield record
    finally:
        with _lock:
            _recordings.remove(record)


def input_at(path: str | os.PathLike[str]) -> str | None:
    """The recorded input (as it was named) that is the file at ``path`` (same inode), else ``None``."""
    with _lock:
        if not _recordings:
            return None
    try:
        st = os.stat(path)
    except OSError:
        return None
    with _lock:
        for record in _recordings:
            found = record.get((st.st_dev, st.st_ino))
            if found is not None:
                return found
    return None


def _iter_chunks(handle: IO[bytes], size: int = 1 * MiB) -> Iterator[bytes]:
    while chunk := handle.read(size):
        yield chunk


def hash_input(path: str | os.PathLike[str], update: Callable[[bytes], object]) -> None:
    """Feed the bytes of the regular file ``path`` to ``update`` (a hash's ``update``) in blocks."""
    with open_input(path) as handle:
        for chunk in _iter_chunks(handle):
            update(chunk)
