"""The mutation audit's table (``benchmarks/mutants.py``) stays true to the code: each mutated snippet
occurs exactly once in its file (so the audit cannot silently mutate nothing, or the wrong line, once
the code moves), each replacement changes it, and each test named to catch it exists."""

from __future__ import annotations

import ast
import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]
_spec = importlib.util.spec_from_file_location("mutants", ROOT / "benchmarks" / "mutants.py")
assert _spec is not None and _spec.loader is not None
mutants = sys.modules.setdefault("mutants", importlib.util.module_from_spec(_spec))
_spec.loader.exec_module(mutants)


def test_names_are_unique_and_the_audit_is_wide():
    names = [m.name for m in mutants.MUTANTS]
    assert len(set(names)) == len(names)
    assert len(names) >= 20


@pytest.mark.parametrize("mutant", mutants.MUTANTS, ids=lambda m: m.name)
def test_each_snippet_occurs_once_and_each_named_test_exists(mutant):
    text = (ROOT / "src" / "brachycal" / mutant.file).read_text()
    assert text.count(mutant.original) == 1, f"{mutant.original!r} occurs {text.count(mutant.original)} times"
    assert mutant.replacement != mutant.original
    ast.parse(text.replace(mutant.original, mutant.replacement))  # the mutant is Python: it fails a test, not an import
    assert mutant.tests
    for node in mutant.tests:
        path, _, name = node.partition("::")
        function = name.partition("[")[0]
        tree = ast.parse((ROOT / path).read_text())
        assert function in {f.name for f in tree.body if isinstance(f, ast.FunctionDef)}, node
