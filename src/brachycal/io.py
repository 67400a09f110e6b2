"""Files: every output of a command written all or nothing, JSON and CSV tables, input hashes, bundled data.

Design: ``docs/design/files.md``, "Outputs: all or nothing".
"""

from __future__ import annotations

import contextlib
import csv
import errno
import hashlib
import json
import math
import os
import re
import secrets
import shutil
import signal
import stat
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from types import TracebackType
from typing import IO

from brachycal.errors import OutputError
from brachycal.inputs import file_kind, hash_input, input_at

__all__ = [
    "OutputSet",
    "atomic_open",
    "atomic_path",
    "bundled",
    "json_text",
    "output_set",
    "sha256_bytes",
    "sha256_file",
    "staged_destination",
    "write_csv",
    "write_json",
]

try:  # POSIX; elsewhere the claim falls back to an exclusive lock file (a killed holder's stays)
    import fcntl
except ImportError:  # pragma: no cover - not on Linux or macOS
    fcntl = None  # type: ignore[assignment]

LOCK_SUFFIX = ".brachycal-lock"
STAGE_MARK = ".brachycal-"

# Staging path -> destination of every live OutputSet in this process. Lets a one-file writer
# (``atomic_open``) called with a staging path write it directly: its set already claimed it.
_STAGED: dict[str, Path] = {}

# Errors of writing itself, which an OSError may carry without a file name (a buffered write
# that fails at flush or close): named after the outputs being written.
_WRITE_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO, errno.EROFS, errno.EACCES, errno.EPERM}


@dataclass
class _Claim:
    destination: Path
    staging: Path
    lock_path: Path | None = None
    lock_fd: int | None = None
    folder: _Claim | None = None  # the new folder it is staged in (its destination the folder)


class OutputSet:
    """All the outputs of one command, written all or nothing.

    Use as a context manager: claim every destination first (:meth:`claim`), write each to the
    staging path it returns, and leave the block; the outputs are moved into place only if the
    block ends without an exception (:meth:`commit`), otherwise everything is removed
    (:meth:`abort`). ::

        with OutputSet(force=args.force) as out:
            csv_path = out.claim(args.out, label="--out")
            png_path = out.claim(args.figure, label="--figure")
            ...  # compute, then write csv_path and png_path

    Args:
        force: replace existing regular files (never directories or special files).
            Folders the outputs need that do not exist yet are never replaced: each is staged
            whole, as a hidden sibling, and appears with its outputs at the commit.
        inputs: the command's input files (a folder stands for the files in it), declared so
            that an output naming one is refused when claimed, before any work; inputs read
            under the command line are refused anyway, when the set is committed.

    Raises (from :meth:`claim` and :meth:`commit`):
        OutputError: naming the destination — exists without ``force``, not a regular file,
            folder missing or not a folder, another brachycal process is writing it, two outputs
            share it, or an OS error (permission denied, read-only file system, disk full).
    """

    def __init__(self, *, force: bool = False, inputs: Sequence[str | os.PathLike[str] | None] = ()) -> None:
        self.force = force
        self._inputs = _declared(inputs)
        self._claims: dict[str, _Claim] = {}  # key: the destination's resolved path
        self._folders: dict[str, _Claim] = {}  # new folders, staged whole (key: their resolved path)
        self._labels: dict[str, str] = {}
        self._token = secrets.token_hex(4)
        self._closed = False
        self.written: list[Path] = []

    # --- claiming ------------------------------------------------------------------------------
    def claim(self, destination: str | os.PathLike[str], *, make_parents: bool = False, label: str = "") -> Path:
        """Claim ``destination`` for this set; returns the staging path to write it to.

        Args:
            destination: the final path of the output.
            make_parents: stage missing folders with the outputs: the topmost one is written
                as a hidden sibling (``.<folder>.brachycal-<token>``) and renamed into place at
                the commit, so a failed or killed command leaves no visible folder; otherwise a
                missing folder is refused.
            label: what the destination is to the user (``"--out"``), for the error when two
                outputs of the command share a path.
        """
        if self._closed:
            raise RuntimeError("this OutputSet is closed")
        destination = Path(destination)
        key = _key(destination)
        if key in self._claims:
            first = self._labels.get(key) or "another output"
            this = label or "an output"
            raise OutputError(
                f"{this} and {first} of this command are the same file; give them different paths",
                file=destination,
            )
        _refuse_special(destination)
        _refuse_input(destination, self._inputs)
        new_folder = self._missing_folder(destination.parent, make_parents)
        if new_folder is not None:
            return self._claim_in_new_folder(destination, key, new_folder, label)
        claim = _Claim(destination, _staging_name(destination, self._token))
        self._claims[key] = claim
        self._labels[key] = label
        with _signals_deferred():  # an interrupt between creating the lock file and recording it would leak it
            claim.lock_path, claim.lock_fd, exclusive = _lock(destination)
        if exclusive:
            _remove_stale_staging(destination)
        # Checked with the lock held: a brachycal writer that committed just before us is seen.
        if os.path.lexists(destination) and not self.force:
            raise OutputError(f"already exists; pass {OutputError.FORCE} to replace it", file=destination)
        _STAGED[str(claim.staging)] = destination
        return claim.staging

    def path(self, destination: str | os.PathLike[str], *, make_parents: bool = False) -> Path:
        """The staging path of ``destination``, claiming it if this set has not yet."""
        claim = self._claims.get(_key(Path(destination)))
        if claim is not None:
            return claim.staging
        return self.claim(destination, make_parents=make_parents)

    def release(self, destination: str | os.PathLike[str]) -> None:
        """Give up a claimed output that will not be written after all (the existing file stays)."""
        claim = self._claims.pop(_key(Path(destination)))
        _remove(claim.staging)
        _STAGED.pop(str(claim.staging), None)
        _unlock(claim)

    @property
    def destinations(self) -> list[Path]:
        """The claimed destinations, in the order claimed."""
        return [c.destination for c in self._claims.values()]

    def _missing_folder(self, folder: Path, make_parents: bool) -> Path | None:
        """The topmost missing folder above an output (None: its folder exists).

        Raises:
            OutputError: a path on the way is not a folder, or a folder is missing without
                ``make_parents``.
        """
        folder = folder if str(folder) else Path(".")
        if folder.is_dir():
            return None
        if folder.exists() or folder.is_symlink():
            raise OutputError("is not a folder", file=folder)
        if not make_parents:
            raise OutputError("folder does not exist", file=folder)
        top = folder
        while top.parent != top and not top.parent.is_dir():
            if top.parent.exists() or top.parent.is_symlink():
                raise OutputError("is not a folder", file=top.parent)
            top = top.parent
        return top

    def _claim_in_new_folder(self, destination: Path, key: str, top: Path, label: str) -> Path:
        """Claim ``destination`` below ``top``, a folder that does not exist: staged in a hidden
        sibling of ``top`` that this set claims (and locks) as a whole."""
        folder = self._folders.get(_key(top))
        if folder is None:
            folder = self._claim_folder(top)
            if folder is None:  # another process made ``top`` meanwhile: an ordinary claim now
                return self.claim(destination, make_parents=True, label=label)
        staging = folder.staging / destination.relative_to(top)
        try:
            staging.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise OutputError(f"cannot create the folder ({exc.strerror})", file=destination.parent) from None
        claim = _Claim(destination, staging, folder=folder)
        self._claims[key] = claim
        self._labels[key] = label
        _STAGED[str(staging)] = destination
        return staging

    def _claim_folder(self, top: Path) -> _Claim | None:
        """Lock the new folder ``top`` and make its hidden staging folder; None if ``top`` exists now."""
        folder = _Claim(top, _staging_name(top, self._token))
        with _signals_deferred():  # an interrupt must not leak the lock or the staging folder
            folder.lock_path, folder.lock_fd, exclusive = _lock(top)
            self._folders[_key(top)] = folder
        if exclusive:
            _remove_stale_staging(top)
        if os.path.lexists(top):
            del self._folders[_key(top)]
            _unlock(folder)
            return None
        with _signals_deferred():
            try:
                folder.staging.mkdir()
            except OSError as exc:
                raise OutputError(f"cannot create the folder ({exc.strerror})", file=top) from None
            _STAGED[str(folder.staging)] = top
        return folder

    # --- ending --------------------------------------------------------------------------------
    def commit(self) -> list[Path]:
        """Move every staged output into place, all or none; returns the destinations."""
        if self._closed:
            raise RuntimeError("this OutputSet is closed")
        moved: list[tuple[Path, Path | None]] = []  # (destination, kept old file or None)
        folders: list[_Claim] = []  # new folders moved into place
        try:
            for claim in self._claims.values():
                if not claim.staging.exists():
                    raise OutputError("was not written (a brachycal bug; please report it)", file=claim.destination)
            for claim in self._claims.values():
                if claim.folder is None:
                    moved.append((claim.destination, self._move_into_place(claim)))
            for folder in self._folders.values():
                _move_folder_into_place(folder)
                folders.append(folder)
        except BaseException:
            for folder in reversed(folders):
                with contextlib.suppress(OSError):
                    os.rename(folder.destination, folder.staging)
            for destination, old in reversed(moved):
                with contextlib.suppress(OSError):
                    if old is not None:
                        os.replace(old, destination)
                    else:
                        destination.unlink()
            self.abort()
            raise
        for _, old in moved:
            if old is not None:
                _remove(old)
        self.written = [claim.destination for claim in self._claims.values()]
        self._close()
        return self.written

    def _move_into_place(self, claim: _Claim) -> Path | None:
        destination = claim.destination
        _refuse_special(destination)  # in case one appeared while the command ran
        _refuse_input(destination, self._inputs)  # the command read it after claiming it
        try:
            if not os.path.lexists(destination):
                _link_new(claim.staging, destination, self.force)
                return None
            if not self.force:
                raise OutputError(
                    f"already exists (made while it was being written); pass {OutputError.FORCE} to replace it",
                    file=destination,
                )
            old = destination.with_name(f".{destination.name}{STAGE_MARK}{self._token}-old")
            _keep_old(destination, old)
            try:
                os.replace(claim.staging, destination)
            except BaseException:
                _remove(old)
                raise
            return old
        except OutputError:
            raise
        except OSError as exc:
            raise OutputError(f"cannot write ({exc.strerror or exc})", file=destination) from None

    def abort(self) -> None:
        """Remove every staged file, lock and folder this set created; existing files stay."""
        if self._closed:
            return
        for claim in self._claims.values():
            with contextlib.suppress(OSError):  # best effort: the error that ended the set is the one to report
                _remove(claim.staging)
        for folder in self._folders.values():
            _remove_tree(folder.staging)
        self._close()

    def _close(self) -> None:
        for claim in [*self._claims.values(), *self._folders.values()]:
            _STAGED.pop(str(claim.staging), None)
            _unlock(claim)
        self._closed = True

    def __enter__(self) -> OutputSet:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, traceback: TracebackType | None
    ) -> None:
        if error is None:
            self.commit()
            return
        named = self._name_os_error(error)
        self.abort()
        if named is not None:
            raise named from None

    def _name_os_error(self, error: BaseException) -> OutputError | None:
        """An OS error of writing a staged file, as an OutputError naming its destination."""
        if not isinstance(error, OSError) or isinstance(error, OutputError):
            return None
        reason = error.strerror or str(error)
        if error.filename is not None:
            destination = self._destination_of(str(error.filename))
            return None if destination is None else OutputError(f"cannot write ({reason})", file=destination)
        if error.errno in _WRITE_ERRNOS and self._claims:
            destinations = self.destinations
            where = destinations[0] if len(destinations) == 1 else _common_folder(destinations)
            return OutputError(f"cannot write the outputs ({reason})", file=where)
        return None

    def _destination_of(self, staged: str) -> Path | None:
        """The final path of a staged file or of a path inside a new folder's staging folder."""
        destination = _STAGED.get(staged)
        if destination is not None:
            return destination
        for folder in self._folders.values():
            with contextlib.suppress(ValueError):
                return folder.destination / Path(staged).relative_to(folder.staging)
        return None


def _staging_name(destination: Path, token: str) -> Path:
    """``.<name>.brachycal-<token><suffix>`` beside ``destination`` (the suffix kept for writers that go by it)."""
    return destination.with_name(f".{destination.name}{STAGE_MARK}{token}{destination.suffix}")


def _move_folder_into_place(folder: _Claim) -> None:
    """Rename a new folder's staging folder to the folder (which must still be absent)."""
    if os.path.lexists(folder.destination):
        raise OutputError("already exists (made while it was being written)", file=folder.destination)
    try:
        os.rename(folder.staging, folder.destination)
    except OSError as exc:
        raise OutputError(f"cannot write ({exc.strerror or exc})", file=folder.destination) from None


def _remove_tree(path: Path) -> None:
    """Remove a staging folder this set made, best effort (the error that ended the set is the one to report)."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)


def _key(path: Path) -> str:
    """One spelling per file: the folder resolved (symlinks, ``..``), the name as given."""
    return str(Path(os.path.realpath(path.parent if str(path.parent) else ".")) / path.name)


def _common_folder(paths: list[Path]) -> Path:
    return Path(os.path.commonpath([str(p.parent.absolute()) for p in paths]))


def _refuse_special(destination: Path) -> None:
    """A destination must be a regular file (or absent); ``force`` never replaces anything else."""
    try:
        mode = os.stat(destination).st_mode  # follows a symlink: what it points to counts
    except FileNotFoundError:
        return
    except NotADirectoryError:
        raise OutputError("its folder is not a folder", file=destination) from None
    except OSError as exc:
        raise OutputError(f"cannot check it ({exc.strerror})", file=destination) from None
    if stat.S_ISREG(mode):
        return
    kind = file_kind(mode)
    raise OutputError(
        f"is {kind}; an output must be a regular file (refused even with {OutputError.FORCE})", file=destination
    )


def _declared(inputs: Sequence[str | os.PathLike[str] | None]) -> dict[tuple[int, int], list[str]]:
    """``(st_dev, st_ino) → paths`` of declared input files, and of the files in declared folders."""
    found: dict[tuple[int, int], list[str]] = {}
    for item in inputs:
        if item is None:
            continue
        paths = [Path(item)]
        if paths[0].is_dir():
            paths = [p for p in paths[0].iterdir() if p.is_file()]
        for path in paths:
            with contextlib.suppress(OSError):
                st = os.stat(path)
                found.setdefault((st.st_dev, st.st_ino), []).append(str(path))
    return found


def _refuse_input(destination: Path, declared: Mapping[tuple[int, int], list[str]]) -> None:
    """An output is never one of the command's inputs (the same file, by inode), even with ``force``."""
    source = input_at(destination)
    if source is None and declared:
        with contextlib.suppress(OSError):
            st = os.stat(destination)
            names = declared.get((st.st_dev, st.st_ino), [])
            # another name of it if it has one (a hard link): the input the user knows
            others = [n for n in names if os.path.abspath(n) != os.path.abspath(destination)]
            source = next(iter(others or names), None)
    if source is None:
        return
    same = "" if os.path.abspath(source) == os.path.abspath(destination) else f" ({source})"
    raise OutputError(
        f"is one of the inputs{same}; an output never replaces an input (refused even with {OutputError.FORCE})",
        file=destination,
    )


@contextlib.contextmanager
def _signals_deferred() -> Iterator[None]:
    """Hold SIGINT and SIGTERM back for a few system calls (delivered on exit, the mask restored):
    the lock file must be recorded by its claim before an interrupt can unwind the command."""
    if not hasattr(signal, "pthread_sigmask"):  # pragma: no cover - Windows
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def _lock(destination: Path) -> tuple[Path, int, bool]:
    """Hold ``.<name>.brachycal-lock`` next to ``destination``; refuse if another process holds it.

    Returns the lock file, its descriptor, and whether the lock is the kernel's (``flock``), so
    that no other brachycal process can be writing ``destination`` now."""
    lock_path = destination.with_name(f".{destination.name}{LOCK_SUFFIX}")
    for _ in range(100):
        try:
            if fcntl is None:  # pragma: no cover
                fd = os.open(lock_path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o644)
            else:
                fd = os.open(lock_path, os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0), 0o644)
        except FileExistsError:  # pragma: no cover - only without fcntl
            raise OutputError(
                f"another brachycal process is writing it (or remove {lock_path.name})", file=destination
            ) from None
        except PermissionError as exc:
            if fcntl is not None and os.path.lexists(lock_path) and _stale_lock_removed(lock_path, destination):
                continue  # another user's stale lock file, removed: take it afresh
            raise OutputError(f"cannot write here ({exc.strerror})", file=destination) from None
        except OSError as exc:
            raise OutputError(f"cannot write here ({exc.strerror})", file=destination) from None
        if fcntl is None:  # pragma: no cover
            return lock_path, fd, False
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.read(fd, 32).decode(errors="replace").strip()
            os.close(fd)
            who = f" (pid {holder})" if holder.isdigit() else ""
            raise OutputError(f"another brachycal process{who} is writing it", file=destination) from None
        except OSError:  # a file system without flock: the claim is this process's word only
            return lock_path, fd, False
        # The previous holder removes the file as it lets go; if it did so between our open and
        # our flock, we hold a lock on a removed file: start again with the file at the path.
        try:
            same = os.path.samestat(os.fstat(fd), os.stat(lock_path))
        except FileNotFoundError:
            same = False
        if same:
            with contextlib.suppress(OSError):  # a full disk: the lock holds without its holder's pid
                os.ftruncate(fd, 0)
                os.write(fd, f"{os.getpid()}\n".encode())
            return lock_path, fd, True
        os.close(fd)
    raise OutputError("cannot take the lock (it keeps changing)", file=destination)  # pragma: no cover


def _remove_stale_staging(destination: Path) -> None:
    """Remove the staging files (``.<name>.brachycal-<token><suffix>``, ``…-old``) or staging
    folders a killed writer of ``destination`` left: with the destination's lock held, no live
    writer has any."""
    prefix = f".{destination.name}{STAGE_MARK}"
    folder = destination.parent if str(destination.parent) else Path(".")
    try:
        names = [entry.name for entry in os.scandir(folder) if entry.name.startswith(prefix)]
    except OSError:
        return
    staging = re.compile(rf"[0-9a-f]{{8}}(?:-old|{re.escape(destination.suffix)})")
    for name in names:
        if not staging.fullmatch(name[len(prefix) :]):
            continue
        stale = folder / name
        if stale.is_dir() and not stale.is_symlink():
            _remove_tree(stale)
            continue
        with contextlib.suppress(OSError):
            stale.unlink()


def _stale_lock_removed(lock_path: Path, destination: Path) -> bool:
    """A lock file this process may not open for writing (another user's): refuse naming its
    holder if it is held, else remove it (stale: its holder died) and say whether that worked.

    Raises:
        OutputError: the lock is held (another brachycal process is writing the destination), or
            it is stale and cannot be removed (naming the lock file to remove).
    """
    try:
        fd = os.open(lock_path, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0))
    except OSError:
        return False  # cannot even read it: the folder's permission error is the one to report
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.read(fd, 32).decode(errors="replace").strip()
            who = f" (pid {holder})" if holder.isdigit() else ""
            raise OutputError(f"another brachycal process{who} is writing it", file=destination) from None
        except OSError:
            return False
    finally:
        os.close(fd)
    try:
        lock_path.unlink()
    except FileNotFoundError:
        return True
    except OSError:
        raise OutputError(
            f"a stale lock file of another user, {lock_path.name}, is in the way (its writer is gone): remove it",
            file=destination,
        ) from None
    return True


def _unlock(claim: _Claim) -> None:
    if claim.lock_fd is None or claim.lock_path is None:  # _lock sets both or neither
        return
    with contextlib.suppress(OSError):
        os.unlink(claim.lock_path)  # while still holding it: see _lock
    with contextlib.suppress(OSError):
        os.close(claim.lock_fd)
    claim.lock_fd = None


def _link_new(staging: Path, destination: Path, force: bool) -> None:
    """Put ``staging`` at ``destination``, which was absent: a hard link never replaces a file
    that appeared meanwhile (without ``force``); file systems without hard links get a rename."""
    try:
        os.link(staging, destination, follow_symlinks=False)
    except FileExistsError:
        if not force:
            raise OutputError(
                f"already exists (made while it was being written); pass {OutputError.FORCE} to replace it",
                file=destination,
            ) from None
        os.replace(staging, destination)
        return
    except OSError as exc:
        if exc.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV, errno.EMLINK, errno.ENOSYS):
            raise
        os.replace(staging, destination)
        return
    _remove(staging)


def _keep_old(destination: Path, old: Path) -> None:
    """Keep the file being replaced at ``old`` until the set is committed (a hard link, or a copy)."""
    try:
        os.link(destination, old, follow_symlinks=False)
    except OSError as exc:
        if exc.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV, errno.EMLINK, errno.ENOSYS):
            raise

        shutil.copy2(destination, old, follow_symlinks=False)


def _remove(path: Path) -> None:
    """Remove ``path`` if it is there (a read-only file system refuses even to unlink nothing)."""
    try:
        path.unlink()
    except FileNotFoundError:
        pass
    except OSError:
        if os.path.lexists(path):
            raise


def output_set(outputs: OutputSet | None, *, force: bool = False) -> contextlib.AbstractContextManager[OutputSet]:
    """``outputs`` if a caller's set is given (it commits), else a new set of this writer's own.

    For library functions that write several files (``write_exports``, ``write_twin``, the HTML
    report): called alone they are all or nothing by themselves; called by a command they join
    its set, so the command's outputs are committed together.
    """
    return contextlib.nullcontext(outputs) if outputs is not None else OutputSet(force=force)


# --- one file ------------------------------------------------------------------------------------
def staged_destination(path: str | os.PathLike[str]) -> Path | None:
    """The destination a staging path of a live :class:`OutputSet` stands for, else ``None``."""
    return _STAGED.get(str(path))


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str], *, force: bool = False) -> Iterator[Path]:
    """A path to write ``path`` to, committed when the block succeeds (a one-output :class:`OutputSet`).

    If ``path`` is already a staging path of a live set (a writer called by a command that
    claimed its outputs), it is yielded as is: that set commits it with the others.
    """
    if staged_destination(path) is not None:
        yield Path(path)
        return
    with OutputSet(force=force) as outputs:
        yield outputs.claim(path)


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike[str], *, force: bool = False) -> Iterator[IO[str]]:
    """Open ``path`` for writing text (``newline=""``) through :func:`atomic_path`."""
    with atomic_path(path, force=force) as staged, open(staged, "w", newline="") as handle:
        yield handle


# --- JSON ----------------------------------------------------------------------------------------
def json_text(payload: object, *, file: str | os.PathLike[str] | None = None, indent: int | None = 2) -> str:
    """``payload`` as JSON text (with a final newline); never NaN or Infinity.

    Raises:
        OutputError: naming the first key whose value is not a finite number (``loocv.icp.mae_mm``),
            and ``file`` (its destination, if ``file`` is a staging path).
    """
    try:
        return json.dumps(payload, indent=indent, allow_nan=False) + "\n"
    except ValueError:
        key, value = _first_non_finite(payload, "") or ("", None)
        where = staged_destination(file) if file is not None else None
        raise OutputError(
            f"{key or 'the value'} is {value!r}, not a finite number; JSON cannot hold it",
            file=where or file,
        ) from None


def _first_non_finite(value: object, key: str) -> tuple[str, float] | None:
    """``(key, value)`` of the first float that is NaN or infinite, depth first; ``None`` if none."""
    if isinstance(value, float):
        return None if math.isfinite(value) else (key, value)
    if isinstance(value, dict):
        items = ((f"{key}.{k}" if key else str(k), v) for k, v in value.items())
    elif isinstance(value, list | tuple):
        items = ((f"{key}[{i}]", v) for i, v in enumerate(value))
    else:
        return None
    for sub_key, sub_value in items:
        found = _first_non_finite(sub_value, sub_key)
        if found is not None:
            return found
    return None


def write_json(path: str | os.PathLike[str], payload: object, *, force: bool = False, indent: int | None = 2) -> Path:
    """Write ``payload`` as JSON through :func:`atomic_open` (no NaN/Infinity: :func:`json_text`)."""
    text = json_text(payload, file=path, indent=indent)
    with atomic_open(path, force=force) as handle:
        handle.write(text)
    return Path(path)


def write_csv(
    path: str | os.PathLike[str],
    rows: Sequence[Mapping[str, object]],
    *,
    float_format: str | None = None,
    force: bool = False,
) -> Path:
    """Write ``rows`` (dicts with the same keys) as a CSV table with a header, through :func:`atomic_open`.

    The columns are the first row's keys, in order; lines end in ``\\n``. With ``float_format``
    (``".6f"``) every float is written with it, otherwise as Python prints it.

    Raises:
        OutputError: no rows (a table without a header says nothing), or the file cannot be written.
    """
    if not rows:
        raise OutputError("no rows to write", file=staged_destination(path) or path)
    with atomic_open(path, force=force) as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        for row in rows:
            if float_format is None:
                writer.writerow(row)
            else:
                writer.writerow({k: (format(v, float_format) if isinstance(v, float) else v) for k, v in row.items()})
    return Path(path)


# --- input hashes --------------------------------------------------------------------------------
def sha256_bytes(data: bytes | str) -> str:
    """Hex SHA-256 of ``data`` (text is hashed as UTF-8): what results record of their inputs."""
    return hashlib.sha256(data.encode() if isinstance(data, str) else data).hexdigest()


def sha256_file(path: str | os.PathLike[str]) -> str:
    """Hex SHA-256 of a file's bytes, or of a folder's files (a ROS 2 bag): each file's path
    relative to the folder, a NUL byte and its bytes, in sorted order. The provenance results and
    reports record for each input."""
    path = Path(path)
    digest = hashlib.sha256()
    if not path.is_dir():
        hash_input(path, digest.update)
        return digest.hexdigest()
    for item in sorted(p for p in path.rglob("*") if p.is_file()):
        digest.update(str(item.relative_to(path)).encode() + b"\0")
        hash_input(item, digest.update)
    return digest.hexdigest()


def bundled(*parts: str) -> Path:
    """Path of bundled data (``urdf/…``, ``examples/…``): in an installed wheel, or the source tree."""
    packaged = resources.files("brachycal")
    for part in parts:
        packaged = packaged.joinpath(part)
    if packaged.is_file() or packaged.is_dir():
        return Path(str(packaged))
    return Path(__file__).resolve().parents[2].joinpath(*parts)
