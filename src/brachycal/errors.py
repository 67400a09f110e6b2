"""The errors and warnings brachycal raises: one small family, one subclass per kind of failure.

Every failure is a :class:`BrachycalError` whose message is one line. The CLI prints it and exits
with code 2; library users catch the base class, or the kind they can handle:

- :class:`InputError` — bad input: a file, a row, a value or an option. The message names the place
  (file, row, column, or a settings file's key) and the problem. Also a ``ValueError``, so
  ``except ValueError`` keeps working.
- :class:`DegenerateDataError` — the input is well formed but cannot determine what is asked
  (all touches at one pose, samples without spread, rotations about one axis). An ``InputError``:
  the data must change.
- :class:`SolverError` — a numerical solver did not reach a solution (IK without a solution,
  a QP the solver rejected). Not the input's fault as such; retries catch only this kind.
- :class:`OutputError` — an output cannot be written (exists without ``--force``, a special file,
  another process is writing it, an OS error).

Warnings use :class:`BrachycalWarning` (and :class:`ConditioningWarning` for estimates that the
data determine only poorly), raised with :func:`warnings.warn`; the CLI prints each as one line.
"""

from __future__ import annotations

from os import PathLike

__all__ = [
    "BrachycalError",
    "BrachycalWarning",
    "ConditioningWarning",
    "DegenerateDataError",
    "InputError",
    "OutputError",
    "SolverError",
]


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


class BrachycalError(Exception):
    """Base of every brachycal error; ``str(error)`` is one line."""

    def __init__(self, message: str) -> None:
        self.problem = message
        super().__init__(_one_line(message))


class InputError(BrachycalError, ValueError):
    """Bad input: one line naming the place (file, row, column) and the problem.

    ``row`` counts lines of a text file from 1 with the header as row 1 (what a spreadsheet
    shows); for other sources ``row_label`` says what is counted (e.g. ``"message"``). ``key``
    names a value of a settings file (TOML, JSON) by its dotted path, ``"image.sector.apex_px"``.
    """

    def __init__(
        self,
        message: str,
        *,
        file: str | PathLike[str] | None = None,
        row: int | None = None,
        column: str | None = None,
        row_label: str = "row",
        key: str | None = None,
    ) -> None:
        self.file = None if file is None else str(file)
        self.row = row
        self.row_label = row_label
        self.column = column
        self.key = key
        where = []
        if self.file is not None:
            where.append(self.file)
        if row is not None:
            where.append(f"{row_label} {row}")
        if column is not None:
            where.append(f"column {column!r}")
        if key is not None:
            where.append(f"key {key!r}")
        text = ": ".join([", ".join(where), message]) if where else message
        super().__init__(text)
        self.problem = message


class DegenerateDataError(InputError):
    """Well-formed data that cannot determine the estimate (the conditioning check failed)."""


class SolverError(BrachycalError, RuntimeError):
    """A numerical solver found no solution (IK, QP); the message says what was asked of it."""


class OutputError(BrachycalError, OSError):
    """An output cannot be written: exists (no ``--force``), special file, busy, or an OS error."""

    def __init__(self, message: str, *, file: str | PathLike[str] | None = None) -> None:
        self.file = None if file is None else str(file)
        super().__init__(f"{self.file}: {message}" if self.file is not None else message)
        self.problem = message


class BrachycalWarning(UserWarning):
    """Something the user should know about a result that is still returned."""


class ConditioningWarning(BrachycalWarning):
    """The data determine an estimate only poorly; the message says how uncertain it is."""
