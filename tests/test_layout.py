"""The package's layout (docs/layout.md): every module imports, and an import inside a function says
why it is there.

The layers themselves and the absence of import cycles are import-linter's contracts
(``[tool.importlinter]`` in pyproject.toml, run by ``lint-imports`` in ``make test``).
"""

from __future__ import annotations

import ast
import importlib
import io
import pkgutil
import tokenize
from pathlib import Path

import brachycal

SOURCE = Path(brachycal.__file__).parent
MARK = "# lazy:"


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def function_level_imports(tree: ast.AST) -> list[ast.Import | ast.ImportFrom]:
    """The import statements inside a function (at any depth), outside ``if TYPE_CHECKING:`` blocks."""
    found: list[ast.Import | ast.ImportFrom] = []

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and _is_type_checking(child.test):
                for statement in child.orelse:
                    visit_statement(statement, in_function)
                continue
            visit_statement(child, in_function)

    def visit_statement(node: ast.AST, in_function: bool) -> None:
        if isinstance(node, (ast.Import, ast.ImportFrom)) and in_function:
            found.append(node)
        visit(node, in_function or isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)))

    visit(tree, False)
    return found


def comments_by_line(text: str) -> dict[int, str]:
    return {
        token.start[0]: token.string
        for token in tokenize.generate_tokens(io.StringIO(text).readline)
        if token.type == tokenize.COMMENT
    }


def unmarked_imports(text: str) -> list[int]:
    """Lines of function-level imports with no ``# lazy: <why>`` on one of their own lines (the
    formatter moves a trailing comment to the closing parenthesis of a split import) or on a comment
    line directly above."""
    comments = comments_by_line(text)
    lines = text.splitlines()
    unmarked = []
    for node in function_level_imports(ast.parse(text)):
        above = node.lineno - 1
        own = any(MARK in comments.get(k, "") for k in range(node.lineno, (node.end_lineno or node.lineno) + 1))
        over = above >= 1 and lines[above - 1].lstrip().startswith(MARK)
        if not (own or over):
            unmarked.append(node.lineno)
    return unmarked


def test_every_module_imports():
    """Every module of the package, imported: so the fast tests (``make test``, this one not marked
    ``slow``) load each module, whatever the slow tail holds."""
    names = [m.name for m in pkgutil.walk_packages(brachycal.__path__, "brachycal.")]
    assert len(names) > 100
    for name in names:
        importlib.import_module(name)


def test_function_level_imports_are_marked():
    # An import inside a function is a choice (start-up time, an optional library): it says why,
    # so that one kept there for a reason that has gone (a cycle, say) is hoisted to the top.
    offenders = {}
    for path in sorted(SOURCE.rglob("*.py")):
        lines = unmarked_imports(path.read_text(encoding="utf-8"))
        if lines:
            offenders[str(path.relative_to(SOURCE))] = lines
    assert offenders == {}, f"mark each '{MARK} <why>' or move it to the module's top: {offenders}"


def test_the_marking_rule_sees_what_it_should():
    text = (
        "from typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n    import json\n"
        "def f():\n"
        "    import os  # lazy: start-up\n"
        "    # lazy: start-up (a long reason)\n"
        "    from pathlib import Path\n"
        "    import sys\n"
        "    def g():\n        import re\n"
        "    from json import (\n        dumps,\n        loads,\n    )  # lazy: start-up\n"
        "    return os, Path, sys\n"
    )
    assert unmarked_imports(text) == [8, 10]


def _imports_of(path: Path) -> set[str]:
    """The top-level package of every module ``path`` imports (anywhere in the file)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            names.add(node.module.split(".")[0])
    return names


def test_only_the_command_line_draws_progress_bars():
    # Library work reports progress to a `progress` callback (whole counts); the command line's
    # progress_bar (cli/common.py) draws it, on stderr, and only there is tqdm imported.
    importers = {str(p.relative_to(SOURCE)) for p in sorted(SOURCE.rglob("*.py")) if "tqdm" in _imports_of(p)}
    assert "cli/common.py" in importers  # the rule sees the one that should
    assert {name for name in importers if not name.startswith("cli/")} == set()
