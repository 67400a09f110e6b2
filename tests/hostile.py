"""Harness of the hostile-input suite (``tests/test_hostile_*.py``).

Each suite file holds a table of :class:`Case` rows — a sub-command's arguments, what to put in the
working folder first, and the words the refusal must contain — and runs them all with
:func:`check_refusal`, which states what every refusal must be: exit code 2, exactly one line on
stderr, ``brachycal…: error: …``, no traceback, nothing written or changed in the folder.
"""

from __future__ import annotations

import hashlib
import io
import warnings
from collections.abc import Callable, Sequence
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import dataclass, field
from pathlib import Path

from brachycal.cli.main import main


@dataclass(frozen=True)
class Case:
    """One hostile input.

    ``argv`` may hold ``{tmp}`` (the case's working folder) and any key of the suite's
    ``placeholders`` (e.g. ``{session}``, ``{result}``); ``setup(tmp)`` prepares files there;
    ``expect`` are words (case-insensitive) that the one-line refusal must contain.
    """

    id: str
    argv: Sequence[str]
    expect: Sequence[str] = ()
    setup: Callable[[Path], None] | None = None
    code: int = 2
    marks: Sequence = field(default_factory=tuple)


@dataclass(frozen=True)
class Outcome:
    code: int
    out: str
    err: str


def run_cli(argv: Sequence[str]) -> Outcome:
    """Run ``brachycal ARGV`` in this process; argparse's own exits are caught too."""
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err), warnings.catch_warnings():
        warnings.simplefilter("default")
        try:
            code = main(list(argv))
        except SystemExit as exc:  # argparse: usage errors
            code = int(exc.code or 0)
    return Outcome(code, out.getvalue(), err.getvalue())


def snapshot(folder: Path) -> dict[str, str]:
    """Every file below ``folder`` (hidden ones too) with the SHA-256 of its bytes."""
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "<dir>"
        for p in sorted(folder.rglob("*"))
    }


def expand(argv: Sequence[str], **values: object) -> list[str]:
    return [str(a).format(**{k: str(v) for k, v in values.items()}) for a in argv]


def check_refusal(case: Case, tmp: Path, **placeholders: object) -> Outcome:
    """Run ``case`` in ``tmp`` and assert it is refused as every refusal must be."""
    if case.setup is not None:
        case.setup(tmp)
    before = snapshot(tmp)
    outcome = run_cli(expand(case.argv, tmp=tmp, **placeholders))
    lines = [line for line in outcome.err.splitlines() if line.strip()]
    assert outcome.code == case.code, f"exit {outcome.code}, stderr: {outcome.err!r}"
    assert "Traceback" not in outcome.err, outcome.err
    assert len(lines) == 1, f"want exactly one line on stderr (no warnings, no chatter), got: {outcome.err!r}"
    errors = lines
    assert errors[0].startswith("brachycal") and "error:" in errors[0], errors[0]
    for word in case.expect:
        assert word.lower() in errors[0].lower(), f"{word!r} not in {errors[0]!r}"
    assert snapshot(tmp) == before, "a refused command changed its folder"
    return outcome
