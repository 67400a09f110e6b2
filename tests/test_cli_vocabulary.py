"""One command line: every command group's --help lists its sub-commands, every command that writes
outputs takes the same common options, and a command with a next step names it on a ``next:`` line."""

from __future__ import annotations

import argparse
import contextlib
import io
from collections.abc import Iterator

import pytest
from conftest import ROOT

from brachycal.cli.main import GROUPS, TWO_WORD_COMMANDS, build_parser, main

EXAMPLES = ROOT / "examples"


def _commands(
    parser: argparse.ArgumentParser, words: tuple[str, ...] = ()
) -> Iterator[tuple[tuple[str, ...], argparse.ArgumentParser]]:
    """Every command of the tree (its words after ``brachycal``, its parser): the leaves of the sub-parsers."""
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        yield words, parser
    for action in subs:
        for name, child in action.choices.items():
            yield from _commands(child, (*words, name))


def _options(parser: argparse.ArgumentParser) -> set[str]:
    return {flag for action in parser._actions for flag in action.option_strings}


COMMANDS = dict(_commands(build_parser()))


def _help(words: list[str]) -> str:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main([*words, "--help"]) == 0
    return out.getvalue()


@pytest.mark.parametrize("words", sorted(COMMANDS), ids=" ".join)
def test_a_command_that_writes_outputs_takes_out_force_and_quiet(words):
    """--out names what is written (a command writing into a DIR it is given, examples and session
    template, takes the folder as its argument); --force replaces it; --quiet shows less. A command
    that takes --urdf also takes --robot, the general form."""
    options = _options(COMMANDS[words])
    if "--out" in options:
        assert {"--force", "--quiet"} <= options
    if "--force" in options:
        assert "--quiet" in options
        assert "--out" in options or words in {("examples",), ("session", "template")}
    if "--urdf" in options:
        assert "--robot" in options
    if "--quiet" in options:
        quiet = next(a for a in COMMANDS[words]._actions if "--quiet" in a.option_strings)
        assert quiet.help and quiet.help.startswith("no "), quiet.help


def _sub_command_groups() -> Iterator[tuple[list[str], list[str]]]:
    """(a group's words, its sub-commands' words): argparse's own groups (session, phantom, robot,
    robot identify) and the groups whose default is a command of its own (plan, nwire, stepper)."""

    def walk(parser: argparse.ArgumentParser, words: list[str]) -> Iterator[tuple[list[str], list[str]]]:
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                if words:
                    yield words, list(action.choices)
                for name, child in action.choices.items():
                    yield from walk(child, [*words, name])

    yield from walk(build_parser(), [])
    for group in GROUPS:
        yield [group], [word for (g, word) in TWO_WORD_COMMANDS if g == group]


@pytest.mark.parametrize("group, words", list(_sub_command_groups()), ids=lambda v: " ".join(v))
def test_every_command_group_help_lists_its_sub_commands(group, words):
    shown = " ".join(_help(group).split())
    for word in words:
        assert f"brachycal {' '.join(group)} {word}" in shown or f"{word} " in shown.split("actions:")[-1], word
    if group[0] in GROUPS:  # the groups whose page is its default command's: each spelled in full
        for word in words:
            assert f"brachycal {group[0]} {word}" in shown or f"brachycal {group[0]} [{word}]" in shown, word


def _run(argv: list[str]) -> list[str]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        assert main(argv) == 0, argv
    return out.getvalue().splitlines()


def test_calibrate_names_the_next_commands_and_quiet_leaves_them_out(tmp_path):
    session = str(EXAMPLES / "session_exact")
    result = tmp_path / "result.json"
    lines = _run(["calibrate", session, "--out", str(result)])
    assert lines[-2] == f"next: brachycal locate {result} JOINTS --uv U,V"
    assert lines[-1] == f"      brachycal export {result} --out DIR"
    quiet = _run(["calibrate", session, "--out", str(result), "--force", "--quiet"])
    assert not any(line.startswith("next:") for line in quiet)
    # export: the check before each procedure comes next; plan check's poses give it.
    exported = _run(["export", str(result), "--out", str(tmp_path / "exports")])
    assert exported[-1] == f"next: brachycal verify {result} CHECK_SESSION --out check_record.json"


def test_verify_demo_names_the_checks_to_try(tmp_path):
    folder = tmp_path / "vdemo"
    lines = _run(["verify", "--demo", str(folder)])
    d = folder.as_posix()
    assert lines[-2].startswith(f"next: brachycal verify {d}/result.json {d}/check_unchanged ")
    assert lines[-1].strip().startswith(f"brachycal verify {d}/result.json {d}/check_probe_remounted ")
    # and the commands it names run as written
    for line in lines[-2:]:
        words = line.removeprefix("next:").split()[1:]
        assert main([*words[:-1], str(tmp_path / words[-1])]) in (0, 1)  # PASS or RECALIBRATE


def test_temporal_names_session_build_with_the_lag(tmp_path):
    lines = _run(
        [
            "temporal",
            str(EXAMPLES / "temporal" / "tank_video.mha"),
            str(EXAMPLES / "temporal" / "tank_tracker.mha"),
            "--out",
            str(tmp_path / "lag.json"),
        ]
    )
    assert lines[-1].startswith("next: brachycal session build JOINT_LOG ") and " --lag-s " in lines[-1]


def test_plan_and_plan_check_name_the_next_commands(tmp_path):
    plan = tmp_path / "plan.csv"
    lines = _run(["plan", "--out", str(plan)])
    assert lines[-2] == "next: brachycal session template DIR"
    assert lines[-1].strip().startswith("brachycal session build JOINT_LOG ") and f"--plan {plan} " in lines[-1]
    check_plan = tmp_path / "check.csv"
    check = _run(["plan", "check", "--out", str(check_plan)])
    assert (
        check[-2].startswith("next: brachycal session build JOINT_LOG --check ")
        and f"--plan {check_plan} " in check[-2]
    )
    assert check[-1].strip() == (
        "brachycal verify RESULT CHECK_SESSION --calibration-session SESSION --out check_record.json"
    )


def test_examples_says_what_each_folder_is_for():
    """Every top-level entry of the bundled examples (the scripts as one) has its line."""
    from brachycal.cli.examples import PURPOSES, bundled_example_files

    _, files = bundled_example_files()
    tops = {"make_*.py" if f.parts[0].startswith("make_") else f.parts[0] for f in files}
    assert tops == set(PURPOSES)


@pytest.mark.slow
def test_every_command_examples_says_to_try_runs(tmp_path, monkeypatch):
    """The "try" list covers each example folder's command (the stepper and robot identification
    included), and each runs as printed, from the folder the examples were copied into."""
    monkeypatch.chdir(tmp_path)
    lines = _run(["examples", "examples"])
    tried = [line.strip() for line in lines[lines.index("try (from this folder; the documentation shows more):") + 1 :]]
    for command in (
        "stepper",
        "stepper image",
        "robot identify touches",
        "robot identify tracker",
        "robot identify session",
    ):
        assert any(line.startswith(f"brachycal {command} examples/") for line in tried), command
    for line in tried:
        _run(line.split()[1:])
