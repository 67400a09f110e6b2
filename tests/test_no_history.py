"""The source's words are for its users: no issue numbers, team paths or dates, and short module docstrings.

Comments, docstrings and strings (``--help`` texts and messages among them) state what the code does
now; where a decision came from belongs in the commit messages. A module's docstring says what the
module holds, with the units and frames a caller must know, and points to its design page under
``docs/design/``; the write-up itself lives there (:data:`MAX_MODULE_DOCSTRING_LINES`).
"""

from __future__ import annotations

import ast
import io
import re
import tokenize
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src" / "brachycal"

#: Longest module docstring, lines with its quotes (the longest is a table of URDF joint types).
MAX_MODULE_DOCSTRING_LINES = 26

#: Words that belong to the project's history or to the team's machines, never to its users.
FORBIDDEN = {
    "an issue number": re.compile(r"\bissue\s*#?\d+", re.IGNORECASE),
    "the team's path": re.compile(r"\.\./shared\b"),
    "a date": re.compile(r"\b20\d\d-\d\d-\d\d\b"),
}


def _sources() -> list[Path]:
    return sorted(SRC.rglob("*.py"))


def _words(path: Path) -> list[tuple[int, str]]:
    """``(line, text)`` of every comment and string literal of one source file."""
    tokens = tokenize.generate_tokens(io.StringIO(path.read_text()).readline)
    return [(tok.start[0], tok.string) for tok in tokens if tok.type in (tokenize.COMMENT, tokenize.STRING)]


def test_the_rules_catch_what_they_are_for():
    caught = [
        name
        for name, rule in FORBIDDEN.items()
        for text in ("# see issue 13", "'../shared/reference'", '"""2026-11-29"""')
        if rule.search(text)
    ]
    assert sorted(caught) == sorted(FORBIDDEN)
    assert not FORBIDDEN["an issue number"].search("soft tissue 1540 m/s")


def test_no_issue_numbers_team_paths_or_dates_in_comments_docstrings_or_strings():
    found = [
        f"{path.relative_to(SRC.parent)}:{line}: {name}"
        for path in _sources()
        for line, text in _words(path)
        for name, rule in FORBIDDEN.items()
        if rule.search(text)
    ]
    assert not found, "\n".join(found)


def test_module_docstrings_are_short():
    long = []
    for path in _sources():
        tree = ast.parse(path.read_text())
        if ast.get_docstring(tree) is None:
            continue
        node = tree.body[0]
        lines = (node.end_lineno or node.lineno) - node.lineno + 1
        if lines > MAX_MODULE_DOCSTRING_LINES:
            long.append(f"{path.relative_to(SRC.parent)}: {lines} lines")
    assert not long, (
        f"module docstrings over {MAX_MODULE_DOCSTRING_LINES} lines (move the write-up to docs/design/):\n"
        + "\n".join(long)
    )
