"""The words users read are for them: no issue numbers, team paths or dates, and short module docstrings.

Comments, docstrings and strings (``--help`` texts and messages among them), the README and the
documentation pages state what the code does now; where a decision came from belongs in the commit
messages. The README stays short (:data:`MAX_README_BYTES`) and lists every command, as the
documentation's command table does. A module's docstring says what the
module holds, with the units and frames a caller must know, and points to its design page under
``docs/design/``; the write-up itself lives there (:data:`MAX_MODULE_DOCSTRING_LINES`).
"""

from __future__ import annotations

import argparse
import ast
import io
import re
import tokenize
from pathlib import Path

import pytest

from brachycal.cli.main import COMMANDS, build_parser, joined_command

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "brachycal"
#: The pages users read besides the source: the README and every documentation page.
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
#: The README's size limit: what a lab reads in five minutes (the rest is on the documentation site).
MAX_README_BYTES = 12 * 1024

#: Longest module docstring, lines with its quotes (the longest is a table of URDF joint types).
MAX_MODULE_DOCSTRING_LINES = 26

#: Words that belong to the project's history or to the team's machines, never to its users.
FORBIDDEN = {
    "an issue number": re.compile(r"\bissue\s*#?\d+", re.IGNORECASE),
    "the team's path": re.compile(r"\.\./shared\b"),
    "a date": re.compile(r"\b20\d\d-\d\d-\d\d\b"),
    "the team's machine": re.compile(r"\bbusy (2-core )?machine\b|\bthis (2-core )?(x86_64 )?VM\b"),
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
        for text in ("# see issue 13", "'../shared/reference'", '"""2026-11-29"""', "on the busy 2-core machine")
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


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_no_issue_numbers_team_paths_or_dates_in_the_readme_and_documentation(page):
    found = [
        f"{page.relative_to(ROOT)}:{number}: {name}"
        for number, line in enumerate(page.read_text().splitlines(), 1)
        for name, rule in FORBIDDEN.items()
        if rule.search(line)
    ]
    assert not found, "\n".join(found)


def _help_texts(parser, name: str | None = None) -> list[str]:
    """The ``--help`` text of ``parser`` and of every sub-command under it (``name``: only that one)."""
    texts = [parser.format_help()]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub_name, sub in action.choices.items():
                if name is None or sub_name == name:
                    texts += _help_texts(sub)
    return texts


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_no_issue_numbers_team_paths_or_dates_in_the_help(name):
    texts = _help_texts(build_parser(full=(name,)), name)
    assert len(texts) >= 2  # brachycal --help and the command's own
    found = [
        f"brachycal {name} --help: {rule_name}"
        for text in texts
        for rule_name, rule in FORBIDDEN.items()
        if rule.search(text)
    ]
    assert not found, "\n".join(found)


def test_the_readme_is_short():
    size = len((ROOT / "README.md").read_bytes())
    assert size <= MAX_README_BYTES, f"README.md is {size} bytes: move the detail to docs/"


def _listed_commands(path: Path, heading: str) -> set[str]:
    """The commands named in the first column of the table under ``heading`` of ``path``."""
    text = path.read_text()
    start = text.index(f"\n{heading}\n")
    section = text[start + len(heading) + 2 :].split("\n#", 1)[0]
    names = set()
    for row in re.findall(r"^\| `brachycal ([^`]+)`", section, flags=re.MULTILINE):
        names.add(joined_command(row.split())[0])
    return names


@pytest.mark.parametrize(("page", "heading"), [("README.md", "## Commands"), ("docs/index.md", "## The commands")])
def test_every_command_is_in_the_command_tables(page, heading):
    listed = build_parser(full=()).format_help()
    assert all(name.split("-")[0] in listed for name in COMMANDS)  # brachycal --help lists them all
    assert _listed_commands(ROOT / page, heading) == set(COMMANDS)
