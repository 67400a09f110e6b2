"""Lazy re-exports for package ``__init__`` files (PEP 562), so that importing a package is cheap.

A package lists what it re-exports as ordinary ``from brachycal.x import name`` lines under
``if TYPE_CHECKING:`` (type checkers and readers see them, nothing runs them) and hands them to
:func:`attach`; a name's module is imported the first time the name is asked for. The import lines
stay the one home of what comes from where: :func:`attach` reads them from the package's source.
"""

from __future__ import annotations

import ast
import importlib
import sys
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path
from types import ModuleType
from typing import Any


def _typing_imports(init_file: str) -> dict[str, tuple[str, str]]:
    """``{exported name: (module, name in it)}`` of the ``if TYPE_CHECKING:`` imports of ``init_file``."""
    tree = ast.parse(Path(init_file).read_text(encoding="utf-8"), init_file)
    found: dict[str, tuple[str, str]] = {}
    for node in tree.body:
        if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING":
            for statement in node.body:
                if isinstance(statement, ast.ImportFrom) and statement.module and statement.level == 0:
                    for alias in statement.names:
                        found[alias.asname or alias.name] = (statement.module, alias.name)
    return found


class _LazyPackage(ModuleType):
    """A package whose lazily exported names win over its submodules of the same name.

    ``brachycal.calibration.phantom.hand_eye`` is a function, exported from the module of the same name.
    An eager ``__init__`` bound the name after loading the submodule; lazily, loading the submodule
    later would bind the name to the module instead. This refuses that one binding.
    """

    _lazy_names: Callable[[], dict[str, tuple[str, str]]]

    def __setattr__(self, name: str, value: Any) -> None:
        own_submodule = isinstance(value, ModuleType) and value.__name__ == f"{self.__name__}.{name}"
        if own_submodule and name in self._lazy_names():
            return
        super().__setattr__(name, value)


def attach(
    package: str, init_file: str, deprecated: Mapping[str, str] | None = None
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """A module ``__getattr__`` and ``__dir__`` that import the ``TYPE_CHECKING`` names on first use.

    Args:
        package: the package's ``__name__``.
        init_file: its ``__file__`` (the ``__init__.py`` holding the ``if TYPE_CHECKING:`` imports).
        deprecated: ``{old name: exported name}``: old spellings still given for one release, with
            a :class:`DeprecationWarning` (not stored: each use warns).

    Returns:
        ``(__getattr__, __dir__)`` to assign at the package's top level. A resolved name is stored
        in the package's namespace, so each is looked up once.
    """
    table: dict[str, tuple[str, str]] | None = None

    def names() -> dict[str, tuple[str, str]]:
        nonlocal table
        if table is None:  # read on first use: `import brachycal` alone parses nothing
            table = _typing_imports(init_file)
        return table

    def __getattr__(name: str) -> Any:
        where = names().get(name)
        if where is None and deprecated and name in deprecated:
            new = deprecated[name]
            warnings.warn(f"{package}.{name} is deprecated: use {package}.{new}", DeprecationWarning, stacklevel=2)
            return __getattr__(new)
        if where is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        module, attribute = where
        value = getattr(importlib.import_module(module), attribute)
        vars(sys.modules[package])[name] = value  # found once; also past _LazyPackage's refusal
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(names()))

    module = sys.modules[package]
    vars(module)["_lazy_names"] = names
    module.__class__ = _LazyPackage
    return __getattr__, __dir__


def renamed(module: str, names: Mapping[str, str]) -> Callable[[str], Any]:
    """A module ``__getattr__`` that gives each old name of ``names`` (``{old: new}``) as the new
    one's value, with a :class:`DeprecationWarning` naming the new spelling (kept one release)."""

    def __getattr__(name: str) -> Any:
        new = names.get(name)
        if new is None:
            raise AttributeError(f"module {module!r} has no attribute {name!r}")
        warnings.warn(f"{module}.{name} is deprecated: use {module}.{new}", DeprecationWarning, stacklevel=2)
        return getattr(sys.modules[module], new)

    return __getattr__
