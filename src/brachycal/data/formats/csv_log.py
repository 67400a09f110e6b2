"""CSV tables of joints: joint logs ``time,<joint names…>`` (``docs/conventions.md``), tables of
configurations, and time columns; joint columns in any order.

Extra columns are ignored (``torso_joint_b2`` is checked against ``torso_joint_b1``). Small
tables are read in one pass; numbers are converted in bulk by NumPy, and only when that fails is
the bad field searched for, so that the message can name its row and column.

Joint logs can be long (10⁶ rows and more), so :func:`csv_log_blocks` reads them in blocks of
bytes cut at line ends: each block is parsed by pyarrow's C++ CSV reader (a correctly rounded
float parser, several times faster than NumPy's ``loadtxt``, which the log's read time is made
of), and only a block the fast reader does not take as it is (a bad field, a blank line, a quoted
field, a short row) is read again by the row scan of :func:`read_table`, which names the file, the
row (absolute, header = row 1) and the column of the problem. Memory is one block, whatever the
length of the log.
"""

from __future__ import annotations

import csv
import io
import os
import queue
import re
import threading
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO, TextIO, TypeVar

import numpy as np

from brachycal.data.joint_log import JointLog, JointLogChecker, configurations_from_columns, joint_columns
from brachycal.errors import InputError
from brachycal.inputs import MAX_TABLE_BYTES, open_input
from brachycal.se3 import FloatArray
from brachycal.validate import all_number_texts, number_from_text

if TYPE_CHECKING:  # annotations only: reading a file needs no Pinocchio
    from brachycal.model.robot import Robot


def _open(path: Path) -> TextIO:
    """A CSV table read whole (at most :data:`~brachycal.inputs.MAX_TABLE_BYTES`), as text; a
    UTF-8 byte-order mark at its start (a spreadsheet's export) is dropped."""
    return open_input(path, "r", max_bytes=MAX_TABLE_BYTES, encoding="utf-8-sig")  # type: ignore[return-value]


#: Longest header line of a joint log (bytes): a few hundred joints' names are a few KiB.
MAX_HEADER_BYTES = 1 << 20


def _open_binary(path: Path) -> BinaryIO:
    """A joint log, read in blocks (no cap on its size); :func:`open_csv_log` drops a byte-order mark."""
    return open_input(path)  # type: ignore[return-value]


#: The blanks a field may have around it (after a ``", "`` separator, before a line end).
BLANKS = " \t"
_BLANKS_AROUND = re.compile(rb"[ \t]*([,\n\r])[ \t]*")

#: The refusal of a file whose last line has no line break: a writer cut off mid-line (a full disk, a
#: killed logger, a truncated copy) leaves ``1.608151017`` as ``1.60``, a number that parses.
TRUNCATED = "the last line has no newline: the file may be truncated"


class _Lines:
    """The lines of a text file for :func:`csv.reader`, remembering the last one (to see whether it ended)."""

    def __init__(self, handle: Iterable[str]) -> None:
        self.handle = handle
        self.last = ""

    def __iter__(self) -> Iterator[str]:
        for line in self.handle:
            self.last = line
            yield line


def _unterminated(last: str | bytes) -> bool:
    """Whether ``last`` (a file's last line) holds something but no line break at its end."""
    if isinstance(last, bytes):
        last = last.decode("utf-8", "replace")
    return bool(last.strip()) and not last.endswith(("\n", "\r"))


def _check_header(path: Path, header: list[str], required: list[str]) -> list[str]:
    """``header`` with its names stripped; refuses an empty header, a repeated name, a missing ``required`` one."""
    header = [h.strip() for h in header]
    if not header:
        raise InputError("empty file; expected a header row", file=path)
    for k, name in enumerate(header):
        if name in header[:k]:
            raise InputError("column appears twice", file=path, row=1, column=name)
    for name in required:
        if name not in header:
            raise InputError(f"no {name!r} column in the header", file=path, row=1)
    return header


def _scan_rows(
    path: Path,
    reader: Iterator[list[str]],
    header: list[str],
    line_offset: int,
    limit: int | None = None,
    lines: _Lines | None = None,
    expected: str = "the header has",
) -> tuple[list[int], list[list[str]]]:
    """The row scan: up to ``limit`` records of ``reader`` (a :func:`csv.reader` of ``lines``) and their file rows.

    ``line_offset`` is the number of file lines before the reader's first line. Blanks around a
    field are dropped (``1.5, 2.5`` as ``numpy.savetxt(..., delimiter=", ")`` and spreadsheets
    write it, read as pandas and NumPy read it); blank lines are skipped; a row with another
    number of fields than the header is refused, naming its row (as :data:`TRUNCATED` when it is
    the file's last line and has no newline: a row cut short), the message saying ``expected``
    before the header's count.
    """
    rows: list[int] = []
    records: list[list[str]] = []
    try:
        for fields in reader:
            if not fields or (len(fields) == 1 and not fields[0].strip()):
                continue
            row = line_offset + reader.line_num  # type: ignore[attr-defined]
            if len(fields) != len(header):
                if lines is not None and _unterminated(lines.last):
                    raise InputError(TRUNCATED, file=path, row=row)
                raise InputError(f"has {len(fields)} fields, {expected} {len(header)}", file=path, row=row)
            rows.append(row)
            records.append([field.strip(BLANKS) for field in fields])
            if limit is not None and len(records) >= limit:
                break
    except (csv.Error, UnicodeDecodeError) as exc:
        raise InputError(f"not a readable CSV file ({exc})", file=path) from None
    return rows, records


def read_table(path: Path, required: list[str]) -> tuple[list[str], list[int], list[list[str]]]:
    """Header, row numbers and raw fields of a CSV file with one header row.

    Returns ``(header, rows, records)``; ``rows[i]`` is the file row of ``records[i]`` (header =
    row 1); blank lines are skipped. Checks the header (no duplicates, ``required`` present) and
    that every row has as many fields as the header. All the fields at once: a reader of a long
    table goes through :func:`table_blocks` instead.
    """
    ((header, rows, records),) = table_blocks(path, required, None)  # one block: all the rows
    return header, rows, records


#: Rows of a table :func:`table_blocks` hands on at a time: their fields as Python strings are a
#: few tens of MB, whatever the length of the table.
TABLE_BLOCK_ROWS = 16_384


def table_blocks(
    path: Path, required: list[str], rows_per_block: int | None = TABLE_BLOCK_ROWS
) -> Iterator[tuple[list[str], list[int], list[list[str]]]]:
    """:func:`read_table`'s ``(header, rows, records)``, ``rows_per_block`` records at a time (None:
    all at once); at least one block, empty for a table of a header only.

    Raises:
        InputError: as :func:`read_table`, when the block holding the problem is reached (a last
            line without a newline before its block is handed on).
    """
    with _open(path) as handle:
        lines = _Lines(handle)
        reader = csv.reader(lines)
        try:
            header = next(reader, [])
        except (csv.Error, UnicodeDecodeError) as exc:
            raise InputError(f"not a readable CSV file ({exc})", file=path) from None
        header = _check_header(path, header, required)
        first = True
        while True:
            rows, records = _scan_rows(path, reader, header, 0, limit=rows_per_block, lines=lines)
            last = rows_per_block is None or len(records) < rows_per_block
            if last and _unterminated(lines.last):
                raise InputError(TRUNCATED, file=path, row=reader.line_num)
            if records or first:
                yield header, rows, records
            first = False
            if last:
                return


def read_bare_table(path: Path, columns: list[str]) -> tuple[list[int], FloatArray]:
    """Row numbers and ``(N, len(columns))`` floats of a CSV table without a header row (row 1 is
    data), every row holding exactly ``len(columns)`` numbers; ``columns`` names them in messages.
    Blank lines are skipped; a field that is not a finite number is refused naming its row and column."""
    with _open(path) as handle:
        lines = _Lines(handle)
        reader = csv.reader(lines)
        rows, records = _scan_rows(path, reader, columns, 0, lines=lines, expected="expected")
        if _unterminated(lines.last):
            raise InputError(TRUNCATED, file=path, row=reader.line_num)
    records = [[f.strip() for f in fields] for fields in records]
    return rows, to_float(path, columns, rows, records, columns)


def to_float(
    path: Path, header: list[str], rows: list[int], records: list[list[str]], columns: list[str]
) -> np.ndarray:
    """``(N, len(columns))`` floats of the named columns, each finite and written as a number
    (:func:`~brachycal.validate.number_from_text`); names the row and column of the first bad field."""
    index = [header.index(c) for c in columns]
    text = [[fields[k] for k in index] for fields in records]
    flat = [field for fields in text for field in fields]
    if all_number_texts(flat):  # one regex pass; a field holding a line break passes it, but not the next line
        try:
            values = np.array(flat, dtype=str).astype(float).reshape(len(records), len(columns))
        except ValueError:
            values = np.full((len(records), len(columns)), np.nan)
        if np.isfinite(values).all():
            return values
    for row, fields in zip(rows, text, strict=True):
        for column, field in zip(columns, fields, strict=True):
            x = number_from_text(field)
            if x is None:
                raise InputError(f"{field!r} is not a number", file=path, row=row, column=column)
            if not np.isfinite(x):
                raise InputError(f"value is not a finite number, got {field!r}", file=path, row=row, column=column)
    raise AssertionError("a field was refused in bulk but not alone")  # pragma: no cover


def unique_names(path: Path, header: list[str], rows: list[int], records: list[list[str]], column: str) -> list[str]:
    """The values of ``column`` (``sample``, ``point``), stripped: each non-empty and each once.

    Raises:
        InputError: an empty name, or a name that appears twice (naming both rows).
    """
    k = header.index(column)
    names = [fields[k].strip() for fields in records]
    seen: dict[str, int] = {}
    for row, name in zip(rows, names, strict=True):
        if not name:
            raise InputError(f"empty {column} name", file=path, row=row, column=column)
        if name in seen:
            raise InputError(
                f"{column} {name!r} appears twice (also row {seen[name]})", file=path, row=row, column=column
            )
        seen[name] = row
    return names


#: Bytes of a joint log read, parsed, checked, computed and written at a time. 4 MiB is ~13,000 rows
#: of 16 full-precision numbers: large enough that per-block overheads (pyarrow's set-up, one
#: batch of forward kinematics) are a few per cent, small enough that a block's arrays (a few tens
#: of MB with the poses of several frames) stay far below the 500 MB a command may use.
BLOCK_BYTES = 4 << 20


@dataclass(frozen=True)
class LogBlock:
    """Consecutive samples of a joint log, as read (not yet checked).

    Attributes:
        time: ``(N,)`` seconds.
        values: ``(N, C)`` joint values, columns in the order of the reader's joint names.
        rows: ``(N,)`` file rows (header = row 1) or message numbers (from 1).
        done: bytes (or messages) of the source read so far, for a progress bar.
    """

    time: FloatArray
    values: FloatArray
    rows: np.ndarray
    done: int


@dataclass
class CsvLog:
    """An open CSV joint log: its joint columns, and its samples block by block (:meth:`blocks`).

    Attributes:
        path: the file.
        header: its column names (stripped).
        joints: the joint columns (:func:`~brachycal.data.joint_log.joint_columns`), in header order.
        size: the file's size in bytes (the total of the progress bar).
    """

    path: Path
    header: list[str]
    joints: list[str]
    size: int
    _handle: BinaryIO
    _header_bytes: int

    def blocks(self, block_bytes: int | None = None) -> Iterator[LogBlock]:
        """The samples, ``block_bytes`` (default :data:`BLOCK_BYTES`) of the file at a time, cut at line ends.

        Raises:
            InputError: a field that is not a number, a row with too few or too many fields, text
                that is not UTF-8 CSV, naming the file, row and column (see :func:`to_float`).
        """
        block_bytes = block_bytes or BLOCK_BYTES
        handle = self._handle
        handle.seek(self._header_bytes)
        line = 1  # file lines before the block: the header
        done = self._header_bytes
        leftover = b""
        while True:
            chunk = handle.read(block_bytes)
            data = leftover + chunk
            if not data:
                return
            if chunk:
                cut = data.rfind(b"\n") + 1
                if cut == 0:  # a single line longer than a block: read on
                    leftover = data
                    continue
                data, leftover = data[:cut], data[cut:]
            else:
                leftover = b""
                last = data[data.rfind(b"\n", 0, len(data) - 1) + 1 :]
                if _unterminated(last):  # the last line, with no line break: a cut file
                    lines = data.count(b"\n") + 1
                    raise InputError(TRUNCATED, file=self.path, row=line + lines)
            if b'"' in data:  # a quoted field may hold a line break: the cut above may not be a row's end
                yield from self._scan_from(done, line)
                return
            lines = data.count(b"\n") + (not data.endswith(b"\n"))
            done += len(data)
            parsed = self._fast(data, lines)
            if parsed is None:
                rows, parsed = self._slow(data, line)
            else:
                rows = np.arange(line + 1, line + 1 + lines)
            yield LogBlock(parsed[:, 0], parsed[:, 1:], rows, done)
            line += lines
            if not chunk:
                return

    def _fast(self, data: bytes, lines: int) -> FloatArray | None:
        """``(lines, 1 + J)`` time and joints of a block by pyarrow, or None if it is not that simple."""
        import pyarrow as pa  # lazy: start-up (pyarrow)
        import pyarrow.csv as pa_csv  # lazy: start-up (pyarrow)

        wanted = ["time", *self.joints]
        if b" " in data or b"\t" in data:  # blanks around fields dropped, as the row scan drops them
            data = _BLANKS_AROUND.sub(rb"\1", data).lstrip(b" \t")
            if b" " in data or b"\t" in data:  # a blank inside a field ("1 5"): the row scan names it
                return None
        try:
            table = pa_csv.read_csv(
                pa.py_buffer(data),
                read_options=pa_csv.ReadOptions(column_names=self.header),
                parse_options=pa_csv.ParseOptions(quote_char=False),
                convert_options=pa_csv.ConvertOptions(
                    include_columns=wanted,
                    column_types=dict.fromkeys(wanted, pa.float64()),
                    null_values=[],
                    strings_can_be_null=False,
                ),
            )
        except (pa.ArrowInvalid, pa.ArrowNotImplementedError):
            return None
        if table.num_rows != lines:  # a blank line was skipped: row numbers are the row scan's to give
            return None
        out = np.empty((lines, len(wanted)))
        for k, name in enumerate(wanted):
            column = table.column(name)
            if column.null_count:
                return None
            out[:, k] = column.to_numpy()
        if not np.isfinite(out).all():  # nan, inf, infinity, 1e999: the row scan names it (or refuses it)
            return None
        return out

    def _slow(self, data: bytes, line: int) -> tuple[np.ndarray, FloatArray]:
        """The row scan of one block (``line`` file lines before it): rows and numbers, or the precise refusal."""
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise InputError(f"not a readable CSV file ({exc})", file=self.path) from None
        rows, records = _scan_rows(self.path, csv.reader(io.StringIO(text, newline="")), self.header, line)
        values = to_float(self.path, self.header, rows, records, ["time", *self.joints])
        return np.asarray(rows, dtype=np.int64), values

    def _scan_from(self, offset: int, line: int, rows_per_block: int = 16_384) -> Iterator[LogBlock]:
        """The row scan from byte ``offset`` (``line`` file lines before it) to the end, in blocks of rows."""
        self._handle.seek(offset)
        text = io.TextIOWrapper(self._handle, encoding="utf-8", newline="")
        lines = _Lines(text)
        reader = csv.reader(lines)
        while True:
            rows, records = _scan_rows(self.path, reader, self.header, line, limit=rows_per_block, lines=lines)
            if not records:
                text.detach()
                if _unterminated(lines.last):
                    raise InputError(TRUNCATED, file=self.path, row=line + reader.line_num)
                return
            values = to_float(self.path, self.header, rows, records, ["time", *self.joints])
            yield LogBlock(values[:, 0], values[:, 1:], np.asarray(rows, dtype=np.int64), self.size)

    def close(self) -> None:
        self._handle.close()

    def __enter__(self) -> CsvLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


_Item = TypeVar("_Item")


def prefetched(items: Iterator[_Item]) -> Iterator[_Item]:
    """The items of ``items``, the next one produced in a background thread while the caller works
    on this one.

    pyarrow parses without the GIL, so reading block k + 1 overlaps computing and writing block k
    on a second core. An exception of ``items`` is raised here, in the caller's thread, where it
    would have been raised without the thread; when the caller stops early (an error, SIGTERM),
    the thread is told to stop, closes ``items`` and is waited for.
    """
    handoff: queue.Queue[tuple[str, object]] = queue.Queue(maxsize=1)
    stop = threading.Event()

    def put(message: tuple[str, object]) -> bool:
        while not stop.is_set():
            try:
                handoff.put(message, timeout=0.05)
                return True
            except queue.Full:
                continue
        return False

    def work() -> None:
        try:
            for item in items:
                if not put(("item", item)):
                    break
            else:
                put(("done", None))
        except BaseException as exc:  # handed to the caller's thread, which raises it
            put(("error", exc))
        finally:
            if hasattr(items, "close"):
                items.close()

    thread = threading.Thread(target=work, name="brachycal-read-ahead", daemon=True)
    thread.start()
    try:
        while True:
            kind, value = handoff.get()
            if kind == "item":
                yield value  # type: ignore[misc]
            elif kind == "error":
                raise value  # type: ignore[misc]
            else:
                return
    finally:
        stop.set()
        thread.join()


def open_csv_log(path: str | os.PathLike[str], robot: Robot) -> CsvLog:
    """Open a CSV joint log and check its header: ``time`` present, no column twice.

    Args:
        path: CSV file with a header row ``time,<joint names…>``; time in seconds, joints in
            radians; other columns are ignored.
        robot: the model the joints belong to.

    Raises:
        InputError: unreadable file, empty file, a header without ``time`` or with a repeated name.
    """
    path = Path(path)
    handle = _open_binary(path)
    try:
        first = handle.readline(MAX_HEADER_BYTES + 1)
        if b"\r" in first.rstrip(b"\r\n"):  # csv's own words would be "new-line character seen in unquoted field"
            raise InputError(
                "its lines end in a carriage return alone (old Mac line ends); save it with LF or CRLF line ends",
                file=path,
            )
        if len(first) > MAX_HEADER_BYTES:  # a file without line breaks is not read whole for its header
            raise InputError(f"header line longer than {MAX_HEADER_BYTES >> 10} KiB: not a CSV joint log", file=path)
        try:
            header = next(csv.reader([first.decode("utf-8-sig")]), [])
        except (csv.Error, UnicodeDecodeError) as exc:
            raise InputError(f"not a readable CSV file ({exc})", file=path) from None
        header = _check_header(path, header, ["time"])
        if _unterminated(first):
            raise InputError(TRUNCATED, file=path, row=1)
        size = os.fstat(handle.fileno()).st_size
    except BaseException:
        handle.close()
        raise
    return CsvLog(path, header, joint_columns(robot, header), size, handle, len(first))


def csv_log_blocks(
    path: str | os.PathLike[str],
    robot: Robot,
    *,
    block_bytes: int | None = None,
    progress: Callable[[int], None] | None = None,
) -> Iterator[tuple[LogBlock, FloatArray]]:
    """A CSV joint log checked block by block: ``(block, q (N, nq) radians in the robot's joint order)``.

    The checks are those of :func:`read_csv_log` (through
    :class:`~brachycal.data.joint_log.JointLogChecker`), including time increasing across blocks;
    the last block is followed by the check that the log is not empty and the one warning about
    readings a hair beyond a joint limit. ``progress(n)`` is called with the bytes read by each block.
    The next block is read (parsed) and checked in a background thread (:func:`prefetched`) while
    the caller works on this one; a refusal is raised in the caller's thread when it reaches the
    block (the blocks before it are the caller's as without the thread), and the warning, given by
    :meth:`~brachycal.data.joint_log.JointLogChecker.finish` after the last block, is given there too.

    Raises:
        InputError: one line naming the file, row and column of the first problem.
    """
    with open_csv_log(path, robot) as log:
        checker = JointLogChecker(robot, log.joints, source=str(log.path))

        def checked() -> Iterator[tuple[LogBlock, FloatArray]]:
            for block in log.blocks(block_bytes):
                yield block, checker.check(block.time, block.values, block.rows)

        done = 0
        for block, q in prefetched(checked()):
            if progress is not None:
                progress(block.done - done)
            done = block.done
            if len(q):
                yield block, q
        checker.finish()


def read_csv_log(path: str | os.PathLike[str], robot: Robot) -> JointLog:
    """Read and validate a CSV joint log (all of it in memory; ``brachycal fk`` streams with
    :func:`csv_log_blocks` instead).

    Args:
        path: CSV file with a header row ``time,<joint names…>``; time in seconds, joints in
            radians.
        robot: the model the joints belong to.

    Returns:
        the validated :class:`JointLog`; its ``rows`` are file rows (header = row 1).

    Raises:
        InputError: one line naming the file, row and column of the first problem.
    """
    return joint_log_from_blocks(csv_log_blocks(path, robot), robot, str(Path(path)))


def joint_log_from_blocks(
    blocks: Iterable[tuple[LogBlock, FloatArray]], robot: Robot, source: str, row_label: str = "row"
) -> JointLog:
    """One :class:`JointLog` of streamed, already checked ``(block, q)`` pairs (:func:`csv_log_blocks`,
    :func:`~brachycal.data.formats.bags.bag_log_blocks`)."""
    blocks = list(blocks)
    return JointLog(
        time=np.concatenate([b.time for b, _ in blocks]),
        q=np.concatenate([q for _, q in blocks]),
        joint_names=robot.joint_names,
        source=source,
        rows=np.concatenate([b.rows for b, _ in blocks]),
        row_label=row_label,
    )


def table_configurations(
    path: Path, robot: Robot, header: list[str], rows: list[int], records: list[list[str]]
) -> FloatArray:
    """``(N, nq)`` configurations from the joint columns of a table read by :func:`read_table`.

    Columns that are not joints (:func:`~brachycal.data.joint_log.joint_columns`) are ignored;
    the joints are validated by :func:`~brachycal.data.joint_log.configurations_from_columns`.
    """
    names = joint_columns(robot, header)
    values = to_float(path, header, rows, records, names)
    return configurations_from_columns(robot, names, values, source=str(path), rows=rows)


def read_configurations(path: str | os.PathLike[str], robot: Robot) -> tuple[list[int], FloatArray]:
    """Configurations from a CSV file whose header names the joints, one per row (radians; a joint
    log works: its time column is ignored): ``(rows (N,) file rows, Q (N, nq) in the robot's order)``.

    All of them in memory; :func:`configuration_blocks` streams them.

    Raises:
        InputError: the file has no rows, or a joint is missing, not a number or out of its limits
            (naming the row and column).
    """
    blocks = list(configuration_blocks(path, robot))
    return [row for rows, _ in blocks for row in rows], np.concatenate([Q for _, Q in blocks])


#: Rows of a table of configurations read, checked and handed on at a time (a few MB of text).
CONFIGURATION_BLOCK_ROWS = 16_384


def configuration_blocks(
    path: str | os.PathLike[str], robot: Robot, rows_per_block: int = CONFIGURATION_BLOCK_ROWS
) -> Iterator[tuple[list[int], FloatArray]]:
    """The configurations of :func:`read_configurations`, ``rows_per_block`` rows at a time:
    ``(rows file rows, Q (n, nq) radians in the robot's order)``. Memory is one block, whatever
    the length of the file (a joint log of millions of rows).

    Raises:
        InputError: as :func:`read_configurations`, when the block holding the problem is reached.
    """
    path = Path(path)
    with open_input(path, "r", encoding="utf-8-sig") as handle:  # streamed: no cap on the size
        reader = csv.reader(handle)
        try:
            header = next(reader, [])
        except (csv.Error, UnicodeDecodeError) as exc:
            raise InputError(f"not a readable CSV file ({exc})", file=path) from None
        header = _check_header(path, header, [])
        empty = True
        while True:
            rows, records = _scan_rows(path, reader, header, 0, limit=rows_per_block)
            if not records:
                break
            empty = False
            yield rows, table_configurations(path, robot, header, rows, records)
    if empty:
        raise InputError("no configurations", file=path)


def read_times(path: str | os.PathLike[str]) -> FloatArray:
    """``(M,)`` the ``time`` column of a CSV file, seconds (e.g. the time stamps of ultrasound frames).

    Raises:
        InputError: a file without rows (nothing to evaluate), a time that is not a finite number.
    """
    path = Path(path)
    header, rows, records = read_table(path, ["time"])
    if not records:
        raise InputError("no times (only a header)", file=path)
    return to_float(path, header, rows, records, ["time"])[:, 0]
