"""Start-up of the command line: ``brachycal --help`` loads none of the heavy libraries, and the
packages re-export lazily without changing what their names are.

Results only (what is imported, what a name resolves to); the start-up times are benchmarks
(``benchmarks/startup.py``), not tests. Each check runs in a new interpreter, since this one has
long imported everything.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

import pytest

#: Libraries that each take 0.1-0.5 s to import; none is needed to show the help or parse the options.
HEAVY = ("pinocchio", "scipy", "mink", "matplotlib", "mujoco", "coal")


def fresh(code: str) -> object:
    """Run ``code`` in a new interpreter; it prints one JSON value, returned here."""
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True).stdout
    return json.loads(out.splitlines()[-1])


def heavy_after(statements: str) -> list[str]:
    return fresh(f"import json, sys\n{statements}\nprint(json.dumps([m for m in {HEAVY!r} if m in sys.modules]))")  # type: ignore[return-value]


def test_building_the_command_and_its_help_loads_no_heavy_library():
    build = "from brachycal.cli.main import build_parser\nbuild_parser(full=())"
    assert heavy_after(build) == []
    show_help = (
        "import contextlib, io\nfrom brachycal.cli.main import main\n"
        "with contextlib.redirect_stdout(io.StringIO()) as out:\n    code = main(['--help'])\n"
        "assert code == 0 and 'calibrate' in out.getvalue() and 'plan' in out.getvalue()"
    )
    assert heavy_after(show_help) == []


COMMANDS = [
    "demo",
    "model",
    "fk",
    "plan",
    "plan check",
    "plan excitation",
    "session build",
    "calibrate",
    "locate",
    "export",
    "pivot",
    "nwire",
    "phantom",
    "study",
    "design",
    "tips",
    "verify",
]


@pytest.mark.parametrize("command", COMMANDS)
def test_a_subcommand_help_loads_only_what_its_options_need(command):
    # No sub-command's options need an estimator, planner or figure to be stated: their choices,
    # ranges and defaults live in light modules (labels, settings, robot_accuracy).
    words = [*command.split(), "--help"]
    run = (
        "import contextlib, io\nfrom brachycal.cli.main import main\n"
        f"with contextlib.redirect_stdout(io.StringIO()):\n    assert main({words!r}) == 0"
    )
    assert heavy_after(run) == []


def test_importing_brachycal_loads_nothing_until_a_name_is_used():
    assert heavy_after("import brachycal, brachycal.model, brachycal.planning, brachycal.calibration") == []
    assert "pinocchio" in heavy_after("import brachycal\nbrachycal.Robot")


def test_the_unknown_command_is_refused_in_one_line(capsys):
    from brachycal.cli.main import main

    assert main(["plna", "--out", "x.csv"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "invalid choice: 'plna'" in err


def test_the_full_parser_of_the_command_named_is_built_and_only_its():
    from brachycal.cli.main import build_parser

    sub = next(a for a in build_parser(full=("plan",))._actions if isinstance(a, argparse._SubParsersAction))
    options = {name: {o for a in p._actions for o in a.option_strings} for name, p in sub.choices.items()}
    assert "--edge-mm" in options["plan"]
    assert options["calibrate"] == {"-h", "--help"}  # a stand-in with the one-line help


def test_a_lazily_exported_name_is_the_object_even_next_to_a_submodule_of_that_name():
    # reporting.contact_sheet is a function that lives in the module reporting/contact_sheet.py;
    # loading the module first must not turn the exported name into the module.
    kind = fresh(
        "import json, brachycal.reporting.contact_sheet, brachycal.reporting as r\n"
        "print(json.dumps([callable(r.contact_sheet), type(r.contact_sheet).__name__]))"
    )
    assert kind == [True, "function"]


@pytest.mark.parametrize("package", ["brachycal", "brachycal.model", "brachycal.planning", "brachycal.calibration"])
def test_dir_of_a_lazy_package_lists_its_exports_before_they_are_loaded(package):
    listed = fresh(
        f"import json, importlib\nm = importlib.import_module({package!r})\n"
        "print(json.dumps([n in dir(m) for n in m.__all__]))"
    )
    assert listed and all(listed)
