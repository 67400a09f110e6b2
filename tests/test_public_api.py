"""The public API is the one people use: what the packages export resolves, and the README, the
notebooks and the library itself reach only for it.

Public means: ``brachycal``, its subpackages (``brachycal.calibration``, ...) and its foundation
modules (``brachycal.se3``, ``.errors``, ``.io``, ``.validate``), and of those only the names in
their ``__all__`` (or, where a module has none, names without a leading underscore). The modules
inside the subpackages are implementation; ``brachycal.cli.main`` is the command's entry point.
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
import json
import pkgutil
import re
from pathlib import Path
from types import ModuleType

import pytest

import brachycal

ROOT = Path(__file__).parents[1]
SOURCE = ROOT / "src" / "brachycal"
SUBPACKAGES = sorted(info.name for info in pkgutil.iter_modules([str(SOURCE)]) if info.ispkg and info.name != "cli")
FOUNDATIONS = ("errors", "io", "se3", "validate")
#: Besides the public namespaces: the command's entry point (a notebook runs the command in-process).
ENTRY_POINTS = {"brachycal.cli.main": {"main"}}


def public_namespaces() -> dict[str, ModuleType]:
    names = ["brachycal", *(f"brachycal.{p}" for p in SUBPACKAGES), *(f"brachycal.{m}" for m in FOUNDATIONS)]
    return {name: importlib.import_module(name) for name in names}


def exported(module: ModuleType) -> set[str]:
    if hasattr(module, "__all__"):
        return set(module.__all__)
    return {name for name in vars(module) if not name.startswith("_")}


@pytest.mark.parametrize("package", ["brachycal", *(f"brachycal.{p}" for p in SUBPACKAGES)])
def test_every_exported_name_resolves_and_is_documented(package):
    module = importlib.import_module(package)
    assert module.__doc__ and len(module.__doc__.split()) > 10, f"{package} says what it offers"
    names = module.__all__
    assert len(names) == len(set(names)), f"{package}.__all__ lists a name twice"
    missing = [name for name in names if not hasattr(module, name)]
    assert missing == [], f"{package}.__all__ names what it does not have: {missing}"
    private = [name for name in names if name.startswith("_") and not (name.startswith("__") and name.endswith("__"))]
    assert private == []


def test_every_subpackage_has_an_explicit_public_api():
    assert {
        "calibration",
        "data",
        "export",
        "imaging",
        "model",
        "planning",
        "reporting",
        "simulation",
        "studies",
    } <= set(SUBPACKAGES)
    for package in SUBPACKAGES:
        assert isinstance(importlib.import_module(f"brachycal.{package}").__all__, list)
    assert (SOURCE / "py.typed").is_file()  # type checkers read the hints of an installed brachycal


def private_imports(tree: ast.AST, allowed: dict[str, set[str]] | None = None) -> list[str]:
    """Imports of brachycal names that are not public (``allowed``: public namespaces and their names)."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == "brachycal":
            for alias in node.names:
                name, module = alias.name, node.module
                if allowed is None:  # library code: any module may be imported, but no private name
                    hidden = name.startswith("_") and not name.startswith("__")
                else:
                    submodule = f"{module}.{name}"
                    hidden = not (
                        (module in allowed and name in allowed[module])
                        or submodule in allowed  # ``from brachycal import calibration``
                    )
                if hidden:
                    found.append(f"line {node.lineno}: from {module} import {name}")
        elif isinstance(node, ast.Import) and allowed is not None:
            for alias in node.names:
                if alias.name.split(".")[0] == "brachycal" and alias.name not in allowed:
                    found.append(f"line {node.lineno}: import {alias.name}")
    return found


def is_module(name: str) -> bool:
    try:
        return importlib.util.find_spec(name) is not None
    except ModuleNotFoundError:  # a name inside a module, not a module
        return False


def private_attributes(tree: ast.AST) -> list[str]:
    """``module._name`` uses, where ``module`` is a brachycal module imported under that name."""
    modules = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == "brachycal":
            modules |= {a.asname or a.name for a in node.names if is_module(f"{node.module}.{a.name}")}
        elif isinstance(node, ast.Import):
            modules |= {a.asname for a in node.names if a.asname and a.name.split(".")[0] == "brachycal"}
    return [
        f"line {node.lineno}: {node.value.id}.{node.attr}"
        for node in ast.walk(tree)
        if isinstance(node, ast.Attribute)
        and isinstance(node.value, ast.Name)
        and node.value.id in modules
        and node.attr.startswith("_")
        and not node.attr.startswith("__")
    ]


def allowed_names() -> dict[str, set[str]]:
    namespaces = public_namespaces()
    allowed = {name: exported(module) for name, module in namespaces.items()}
    allowed.update(ENTRY_POINTS)
    return allowed


def test_no_module_imports_a_private_name_of_another():
    offenders = {}
    for path in sorted(SOURCE.rglob("*.py")):
        tree = ast.parse(path.read_text(), str(path))
        found = private_imports(tree) + private_attributes(tree)
        if found:
            offenders[str(path.relative_to(SOURCE))] = found
    assert offenders == {}, "make the name public (or move the code that needs it) instead"


def readme_python_blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.DOTALL)


def test_the_readme_imports_only_public_names():
    blocks = readme_python_blocks()
    assert blocks, "the README shows the Python API"
    allowed = allowed_names()
    for block in blocks:
        assert private_imports(ast.parse(block), allowed) == []


def notebook_code(path: Path) -> str:
    cells = json.loads(path.read_text())["cells"]
    lines = [line for c in cells if c["cell_type"] == "code" for line in "".join(c["source"]).splitlines()]
    return "\n".join(line for line in lines if not line.lstrip().startswith(("%", "!")))  # IPython magics


@pytest.mark.parametrize("notebook", sorted((ROOT / "notebooks").glob("*.ipynb")), ids=lambda p: p.stem)
def test_notebooks_import_only_public_names(notebook):
    assert private_imports(ast.parse(notebook_code(notebook)), allowed_names()) == []


def test_the_readme_python_examples_run(tmp_path, monkeypatch):
    # In a scratch folder that sees the repository's examples (read only), as a reader's clone does.
    (tmp_path / "examples").symlink_to(ROOT / "examples", target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    for k, block in enumerate(readme_python_blocks()):
        exec(compile(block, f"README.md python block {k + 1}", "exec"), {"__name__": f"readme_{k}"})
    assert (tmp_path / "sda10f_calibrated.urdf").is_file()  # what the joint-log example writes


def test_the_top_level_package_offers_the_first_steps():
    # The README's first lines of Python: the robot and a joint log, from ``brachycal`` itself.
    assert {"Robot", "read_joint_log", "JointLog", "InputError", "__version__"} <= set(brachycal.__all__)


#: The main path, from ``brachycal`` itself: robot, session reader, calibrations, result files, the
#: value every consumer takes, plan, check, export, the twin, the errors.
MAIN_PATH = {
    "Robot",
    "load_description",
    "read_session",
    "calibrate",
    "calibrate_chain",
    "calibrate_folder",
    "read_result",
    "write_result",
    "Calibration",
    "locate",
    "plan_poses",
    "check_calibration",
    "write_exports",
    "simulate",
    "BrachycalError",
    "InputError",
    "DegenerateDataError",
    "SolverError",
    "OutputError",
}


def test_the_main_path_is_importable_from_brachycal_itself():
    assert MAIN_PATH <= set(brachycal.__all__)


@pytest.mark.parametrize("name", sorted(brachycal.__all__))
def test_every_top_level_name_imports_and_is_its_homes_object(name):
    namespace: dict[str, object] = {}
    exec(f"from brachycal import {name}", namespace)
    value = namespace[name]
    home = getattr(value, "__module__", None)
    if isinstance(home, str) and home.startswith("brachycal.") and hasattr(importlib.import_module(home), name):
        assert getattr(importlib.import_module(home), name) is value  # an alias, not a copy


def test_the_readme_python_uses_only_import_brachycal():
    for block in readme_python_blocks():
        imports = [n for n in ast.walk(ast.parse(block)) if isinstance(n, ast.Import | ast.ImportFrom)]
        assert all(isinstance(n, ast.Import) and [a.name for a in n.names] == ["brachycal"] for n in imports), (
            "the README's Python reaches the API through `import brachycal` alone"
        )
        used = {
            n.attr
            for n in ast.walk(ast.parse(block))
            if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name) and n.value.id == "brachycal"
        }
        assert used and used <= set(brachycal.__all__)


#: Names that moved from ``brachycal.simulation`` to ``brachycal.studies``.
MOVED_TO_STUDIES = ["run_demo", "run_study", "targeting_error", "TargetingResult", "sweep", "evaluate_design"]


@pytest.mark.parametrize("name", MOVED_TO_STUDIES)
def test_a_study_name_that_left_simulation_is_a_deprecated_top_level_alias(name):
    studies = importlib.import_module("brachycal.studies")
    with pytest.warns(DeprecationWarning, match=rf"use brachycal\.studies\.{name}"):
        value = getattr(brachycal, name)
    assert value is getattr(studies, name)
    assert name not in brachycal.__all__  # deprecated: offered, not advertised


@pytest.mark.parametrize("name", MOVED_TO_STUDIES)
def test_the_old_simulation_path_says_where_a_study_name_went(name):
    with pytest.raises(ImportError, match=rf"moved: use brachycal\.studies\.{name}"):
        exec(f"from brachycal.simulation import {name}", {})


def test_every_name_brachycal_simulation_lost_is_covered():
    simulation = importlib.import_module("brachycal.simulation")
    studies = importlib.import_module("brachycal.studies")
    # studies offers them all (and names of its own since, such as the stepper twin's)
    assert set(simulation._MOVED_TO_STUDIES) == set(brachycal._MOVED_TO_STUDIES) <= set(studies.__all__)


def test_an_unknown_top_level_name_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'not_a_name'"):
        brachycal.not_a_name  # noqa: B018


def renamed_names() -> list[tuple[str, str]]:
    return sorted(importlib.import_module("brachycal.calibration")._RENAMED.items())


@pytest.mark.parametrize(("old", "new"), renamed_names())
def test_a_former_result_or_entry_point_name_still_works_for_one_release_and_warns(old, new):
    calibration = importlib.import_module("brachycal.calibration")
    assert new in calibration.__all__ and old not in calibration.__all__
    with pytest.warns(
        DeprecationWarning, match=rf"calibration\.{old} is deprecated: use brachycal\.calibration\.{new}"
    ):
        value = getattr(calibration, old)
    assert value is getattr(calibration, new)
    home = importlib.import_module(value.__module__)  # the defining module gives the old name too
    with pytest.warns(DeprecationWarning, match=rf"{old} is deprecated: use {re.escape(value.__module__)}\.{new}"):
        assert getattr(home, old) is value


def test_results_and_file_entry_points_follow_one_naming_pattern():
    # Results end in ``Result``, what a file gives back in ``File``, and a method from files is
    # ``calibrate_<method>_files``.
    calibration = importlib.import_module("brachycal.calibration")
    for new in calibration._RENAMED.values():
        assert new.endswith(("Result", "File")) or re.fullmatch(r"calibrate_\w+_files", new), new
