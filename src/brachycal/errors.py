"""The one exception type that brachycal raises for bad input.

Every refusal of a file, a row or a value is an :class:`InputError` whose message is one line
that names where the problem is (file, row, column) and what is wrong. The CLI prints it and
exits with code 2; library users can catch it like any ``ValueError``.
"""

from __future__ import annotations

from os import PathLike


class InputError(ValueError):
    """Bad input: one line naming the place (file, row, column) and the problem.

    ``row`` counts lines of a text file from 1 with the header as row 1 (what a spreadsheet
    shows); for other sources ``row_label`` says what is counted (e.g. ``"message"``).
    """

    def __init__(
        self,
        message: str,
        *,
        file: str | PathLike[str] | None = None,
        row: int | None = None,
        column: str | None = None,
        row_label: str = "row",
    ) -> None:
        self.file = None if file is None else str(file)
        self.row = row
        self.row_label = row_label
        self.column = column
        self.problem = message
        super().__init__(self._one_line())

    def _one_line(self) -> str:
        where = []
        if self.file is not None:
            where.append(self.file)
        if self.row is not None:
            where.append(f"{self.row_label} {self.row}")
        if self.column is not None:
            where.append(f"column {self.column!r}")
        text = ": ".join([", ".join(where), self.problem]) if where else self.problem
        return " ".join(text.split())
