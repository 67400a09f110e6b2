"""Every command the documentation shows runs as written.

The commands are read from the documents themselves: every ``brachycal …`` line of the ```sh
blocks of README.md, docs/procedure.md and docs/guide.md (``\\`` continuations joined, ``# comments`` dropped) and
every line of the ``example:``/``examples:`` section of each sub-command's ``--help``. They run
in-process (``brachycal.cli.main.main``), in document order, README first, then the procedure and the
guide, then the ``--help`` examples, all in one empty folder that holds nothing but what they make: the first
README command is ``brachycal examples examples``, which copies the bundled example files there, as
a user outside a clone does. A command that an earlier document already ran (the same words) is not
run again: the documents repeat a prerequisite (``brachycal demo`` before ``brachycal view``) as a
reminder, and its outputs are already there (running it again would refuse to replace them).

Not run here, each for its stated reason (:data:`NOT_RUN`): long jobs that their own tests run
(``study``, ``design``, robot identification, excitation poses) and the commands on outside
recordings (the reference data, ``$BRACHYCAL_REFERENCE/…``), which :func:`test_commands_on_outside_recordings_run` runs
where that data is. ``brachycal view`` serves until stopped: the walk starts each in a process of
its own (on a free port, ``--port 0`` added), waits for its address and stops it with SIGTERM.
"""

from __future__ import annotations

import argparse
import io
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import threading
import time
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import pytest
from conftest import REFERENCE, ROOT, reference

import brachycal
from brachycal.cli.main import COMMANDS, build_parser, joined_command, main
from brachycal.model.description_file import example_robot_data_share
from brachycal.studies.example_files import TOUCH_PLACES, TOUCH_TOOL_FRAME, TRACKER_NAMES

ROBOTS = example_robot_data_share() / "robots"
DOCUMENTS = [ROOT / "README.md", ROOT / "docs" / "procedure.md", ROOT / "docs" / "guide.md"]
#: Commands on outside data, in the documents and the ``--help`` examples: the folder
#: ``BRACHYCAL_REFERENCE`` names, replaced by :data:`REFERENCE`.
OUTSIDE = "$BRACHYCAL_REFERENCE/"
#: Commands not run by the ordered walk: the sub-command and words it contains, and why. Each is
#: a job of several seconds to minutes of CPU that its own tests run; the walk stays within
#: :data:`CPU_BUDGET_S`.
NOT_RUN = {
    ("study",): "a sweep over twin sessions (5 seeds x 9 settings: minutes of CPU); tests/test_twin.py runs study",
    ("design",): "simulates and calibrates several twin sessions per design (minutes of CPU)",
    ("calibrate", "--identify-robot"): "robot identification with its cross-validation, ~24 s of CPU; "
    "tests/test_robot_identification.py runs it",
    ("robot", "session"): "robot identification with its 8-fold cross-validation, ~5 s of CPU; "
    "tests/test_session_protocol.py runs it",
    ("plan", "excitation"): "identifies the robot, then scores 364 candidate poses, ~11 s of CPU; "
    "tests/test_excitation.py runs it",
    ("demo", "--table3"): "Table III simulates and calibrates a twin per seed by seven methods (~5 s of CPU a "
    "seed); tests/test_phantom_twin.py runs it",
    ("demo", "--images"): "a second demo (~30 s of CPU) plus 66 rendered frames; tests/test_needle_tip.py renders a "
    "twin's recording and runs brachycal tips on it",
    ("tips",): "needs the frames of demo --images (above): ~0.15 s of CPU a frame; tests/test_needle_tip.py runs it",
}
#: CPU budget of the ordered walk in this process, seconds (measured ~40 s on a 2-core x86_64 VM).
CPU_BUDGET_S = 60.0


def _join_continuations(lines: list[str]) -> list[str]:
    joined: list[str] = []
    pending = ""
    for line in lines:
        stripped = line.rstrip()
        if stripped.endswith("\\"):
            pending += stripped[:-1].strip() + " "
            continue
        joined.append((pending + stripped.strip()).strip())
        pending = ""
    return joined


def document_commands(path: Path) -> list[list[str]]:
    """``argv`` (without ``brachycal``) of every ``brachycal`` line in the ```sh blocks of ``path``."""
    commands: list[list[str]] = []
    block: list[str] | None = None
    for line in path.read_text().splitlines():
        if block is None:
            if line.strip().startswith("```sh"):
                block = []
            continue
        if line.strip().startswith("```"):
            for command in _join_continuations(block):
                words = shlex.split(command, comments=True)
                if words and words[0] == "brachycal":
                    commands.append(words[1:])
            block = None
            continue
        block.append(line)
    return commands


def help_commands() -> list[list[str]]:
    """``argv`` of every line of the ``example:``/``examples:`` sections of each sub-command's ``--help``
    (its description and epilog, as argparse prints them).

    An example line is ``brachycal …`` up to two spaces in a row (what follows is its comment).
    """
    commands: list[list[str]] = []
    for name in COMMANDS:
        for text in _help_texts(build_parser(full=(name,)), name):
            commands += _examples(text)
    return commands


def _help_texts(parser: argparse.ArgumentParser, name: str) -> list[str]:
    """The ``--help`` text of sub-command ``name`` and of its own sub-commands (``session build``)."""
    texts: list[str] = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub_name, sub in action.choices.items():
                if sub_name == name or not name:
                    texts.append(sub.format_help())
                    texts += _help_texts(sub, "")
    return texts


def _examples(text: str) -> list[list[str]]:
    """The ``brachycal`` lines of the ``example:``/``examples:`` sections of one help text."""
    commands: list[list[str]] = []
    for match in re.finditer(r"^examples?:\n((?:[ \t]+.*\n?)+)", text, flags=re.MULTILINE):
        for command in _join_continuations(match.group(1).splitlines()):
            words = shlex.split(re.split(r"\s{2,}", command.strip())[0])
            if words and words[0] == "brachycal":
                commands.append(words[1:])
    return commands


def _not_run(argv: list[str]) -> str | None:
    if any(OUTSIDE in word for word in argv):
        return "outside data: test_commands_on_outside_recordings_run"
    return next((why for words, why in NOT_RUN.items() if argv[0] == words[0] and set(words) <= set(argv)), None)


def _unforced(argv: list[str]) -> list[str]:
    return [word for word in argv if word != "--force"]


def _run(argv: list[str]) -> tuple[int, str]:
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        code = main(argv)
    return code, err.getvalue()


def test_the_documents_show_the_commands_this_test_runs():
    """The extraction finds what the documents show (a broken parser must not pass by finding nothing)."""
    readme = document_commands(ROOT / "README.md")
    assert readme[0] == ["examples", "examples"]  # the walk starts in an empty folder
    every = [argv for path in DOCUMENTS for argv in document_commands(path)] + help_commands()
    shown = {joined_command(argv)[0] for argv in every} & set(COMMANDS)  # `nwire segment` is nwire-segment
    # Every sub-command is shown somewhere (model has no --help example: the README shows it).
    assert shown == set(COMMANDS)
    # Continuations joined: the session build of the tour is one command with all its options.
    build = next(argv for argv in readme if argv[:2] == ["session", "build"])
    assert "--template" in build and "--out" in build


#: The order the ``--help`` examples run in (after the documents' commands, in the same folder):
#: each after those that make its inputs (``calibrate`` writes what ``locate`` and ``export`` read).
HELP_ORDER = ["examples", "demo", "model", "fk", "session", "calibrate", "locate", "export", "pivot", "nwire", "plan"]


@pytest.mark.slow
def test_every_documented_command_runs_as_written(tmp_path, monkeypatch):
    """README, then the procedure and the guide, then the --help examples (HELP_ORDER), in one folder."""
    monkeypatch.chdir(tmp_path)
    commands = [(path.name, argv) for path in DOCUMENTS for argv in document_commands(path)]
    shown = sorted(help_commands(), key=lambda argv: HELP_ORDER.index(argv[0]) if argv[0] in HELP_ORDER else 99)
    commands += [(f"brachycal {argv[0]} --help", argv) for argv in shown]
    cpu = time.process_time()
    ran: list[list[str]] = []
    failures: list[str] = []
    for source, argv in commands:
        # The README's tour passes --force (so that it can run again); the same command without it
        # later is the same command, its outputs already there.
        if _unforced(argv) in map(_unforced, ran) or _not_run(argv):
            continue
        ran.append(argv)
        if argv[0] == "view":  # serves until stopped: started in a process of its own and stopped
            _serves(argv, tmp_path)
            continue
        code, err = _run(argv)
        if code != 0:
            failures.append(f"{source}: brachycal {shlex.join(argv)} -> exit {code}: {err.strip()}")
    cpu = time.process_time() - cpu
    assert not failures, "\n".join(failures)
    assert len(ran) >= 20  # 24 distinct commands today: a parser finding far fewer is broken
    # The views' own processes are not counted here (~4 s of CPU each).
    assert cpu < CPU_BUDGET_S, f"the documented commands took {cpu:.0f} s of CPU in this process"


@pytest.mark.slow
def test_commands_on_outside_recordings_run(tmp_path, monkeypatch):
    """The documents' commands on PLUS's and SciKit-Surgery's real recordings, where that data is."""
    reference("sksurgery_pivot", "tracked_pointer_pivot.csv")
    reference("plus_fcal_nwire", "fCal_3NWires_segmented_frames.xml")
    reference("mukca_touches", "data", "panda_2_clean", "front_center", "hole_0.csv")
    monkeypatch.chdir(tmp_path)
    outside = [argv for path in DOCUMENTS for argv in document_commands(path) if any(OUTSIDE in w for w in argv)]
    assert {argv[0] for argv in outside} >= {"pivot", "nwire"}
    for argv in outside:
        argv = [word.replace(OUTSIDE, f"{REFERENCE}/") for word in argv]
        code, err = _run(argv)
        assert code == 0, f"brachycal {shlex.join(argv)}: {err}"


def start_list() -> list[str]:
    """The commands of the ``start here:`` list of ``brachycal --help``, as printed (placeholders kept;
    a line's comment, after two spaces or on the next line, dropped)."""
    text = build_parser(full=()).format_help()
    section = re.search(r"^start here:\n((?:[ \t]+.*\n)+)", text, flags=re.MULTILINE)
    assert section, "brachycal --help has no 'start here:' list"
    lines = _join_continuations([line.strip() for line in section.group(1).splitlines()])
    return [re.split(r"\s{2,}", line)[0] for line in lines if line.startswith("brachycal ")]


def _variants(line: str) -> list[list[str]]:
    """``argv`` of each form a start-list line shows: ``[word]`` with and without the word, each
    alternative of ``a|b|c`` on its own."""
    forms = [[]]
    for word in shlex.split(line)[1:]:
        if word.startswith("[") and word.endswith("]"):
            forms = [*forms, *[[*form, word[1:-1]] for form in forms]]
        elif "|" in word:
            forms = [[*form, choice] for form in forms for choice in word.split("|")]
        else:
            forms = [[*form, word] for form in forms]
    return forms


def _placeholder(word: str) -> bool:
    """A word the reader replaces: LOG, SESSION, FRAMES.mha, U,V, FOLDER... (one or more)."""
    return re.fullmatch(r"[A-Z][A-Z_,]*(\.[a-z]+)?(\.\.\.)?", word) is not None


def _form_name(argv: list[str]) -> str:
    """The literal words a start-list form begins with (``session build``, ``phantom wedge``)."""
    words = []
    for word in argv:
        if word.startswith("-") or _placeholder(word):
            break
        words.append(word)
    return " ".join(words)


#: What each start-list form's placeholders (and its file names that must be an example's) stand for
#: on the bundled data, in the folder :data:`START_SETUP` prepares; a value of several words adds the
#: options the example needs.
START_BINDINGS: dict[str, dict[str, str]] = {
    "fk": {"LOG": "examples/joint_log.csv"},
    "session template": {"DIR": "my_session"},
    "session build": {
        "LOG": "run/recording/joint_log.csv",
        "marks.csv": "run/recording/marks.csv",
        "images.csv": "run/recording/images.csv",
        "session.toml": "run/recording/session.toml",
        "SESSION": "built_session",
    },
    "tips": {"FRAMES.mha": "run/recording/frames.mha"},
    "calibrate": {"SESSION": "examples/twin_session"},
    "locate": {"RESULT": "result.json", "JOINTS": "examples/joints.csv", "U,V": "540,300"},
    "export": {"RESULT": "result.json", "DIR": "exports"},
    "verify": {"RESULT": "vdemo/result.json", "CHECK_SESSION": "vdemo/check_unchanged"},
    "view": {"RESULT": "result.json", "SESSION": "examples/twin_session"},
    "pivot": {"POSES.csv": "examples/pivot/pointer_pivot.csv --units mm"},  # the example's poses are in mm
    "nwire": {
        "CONFIG": "examples/nwire/PlusDeviceSet_twin_fCal2.xml",
        "FRAMES": "examples/nwire/twin_segmented_frames.xml",
    },
    "nwire calibrate": {
        "CONFIG": "examples/nwire/PlusDeviceSet_twin_fCal2.xml",
        "FRAMES": "examples/nwire/twin_segmented_frames.xml",
        "nwire.json": "nwire_calibrate.json",
    },
    "nwire segment": {
        "CAL.mha": "examples/nwire/twin_calibration.mha",
        "VAL.mha": "examples/nwire/twin_validation.mha",
        "CONFIG": "examples/nwire/PlusDeviceSet_twin_fCal2.xml",
    },
    "phantom wedge": {
        "GEOMETRY": "examples/phantom/multi_wedge.toml",
        "OBSERVATIONS": "examples/phantom/wedge_observations.csv",
        "result.json": "phantom_wedge.json",
    },
    "phantom wire": {
        "GEOMETRY": "examples/phantom/arbitrary_wire.toml",
        "OBSERVATIONS": "examples/phantom/wire_observations.csv",
        "result.json": "phantom_wire.json",
    },
    "phantom nwire": {
        "GEOMETRY": "examples/nwire/PlusDeviceSet_twin_fCal2.xml",
        "OBSERVATIONS": "examples/nwire/twin_segmented_frames.xml",
        "result.json": "phantom_nwire.json",
    },
    "temporal": {"VIDEO.mha": "examples/temporal/tank_video.mha", "TRACKER.mha": "examples/temporal/tank_tracker.mha"},
    # The arms' URDFs are example-robot-data's (installed with brachycal: the bundled panda and ur10
    # descriptions read them); a robot named instead of a file (NAME) is the bundled description.
    "robot identify touches": {
        "FOLDER...": " ".join(f"examples/touches/{place}" for place in TOUCH_PLACES),
        "URDF": str(ROBOTS / "panda_description" / "urdf" / "panda.urdf"),
        "FILE": str(ROBOTS / "panda_description" / "urdf" / "panda.urdf"),
        "NAME": "panda",
        "ARM": "panda",
        "FRAME": TOUCH_TOOL_FRAME,
        "PLACE": next(iter(TOUCH_PLACES)),
        "DIR": "touches_identified",
    },
    "robot identify tracker": {
        "TABLE": f"examples/{TRACKER_NAMES[0]}",
        "SPEC": f"examples/{TRACKER_NAMES[1]}",
        "URDF": str(ROBOTS / "ur_description" / "urdf" / "ur10_robot.urdf"),
        "FILE": str(ROBOTS / "ur_description" / "urdf" / "ur10_robot.urdf"),
        "NAME": "ur10",
        "ARM": "ur10",
        "DIR": "tracker_identified",
    },
    **{
        form: {
            "ROTATION.mha": "examples/stepper/twin_ProbeRotation.igs.mha",
            "PROBE_TRANSLATION.mha": "examples/stepper/twin_ProbeTranslation.igs.mha",
            "TEMPLATE_TRANSLATION.mha": "examples/stepper/twin_TemplateTranslation.igs.mha",
            "DEVICE_SET.xml": "examples/stepper/PlusDeviceSet_twin_iCal.xml",
            "stepper.json": out,
        }
        for form, out in (("stepper", "stepper.json"), ("stepper calibrate", "stepper_calibrate.json"))
    },
    "stepper image": {
        "ROTATION.mha": "examples/stepper/twin_ProbeRotation.igs.mha",
        "CAL.mha": "examples/stepper/twin_RandomStepperMotionCalibration.igs.mha",
        "VAL.mha": "examples/stepper/twin_RandomStepperMotionValidation.igs.mha",
        "DEVICE_SET.xml": "examples/stepper/PlusDeviceSet_twin_iCal.xml",
    },
    "stepper template": {
        "RESULT": "stepper_image.json",
        "DEVICE_SET.xml": "examples/stepper/PlusDeviceSet_twin_iCal.xml",
    },
    "stepper export": {"RESULT": "stepper_image.json", "DIR": "stepper_exports"},
}
#: Run first, in the start list's folder: the example files, a recording with its frames (session
#: build, tips) and a check session (verify).
START_SETUP = [
    ["examples", "examples"],
    ["demo", "--recording", "--images", "--out", "run"],
    ["verify", "--demo", "vdemo"],
]


def _bound(argv: list[str]) -> list[str]:
    binding = START_BINDINGS.get(_form_name(argv), {})
    words = [part for word in argv for part in binding.get(word, word).split()]
    unbound = [word for word in words if _placeholder(word)]
    assert not unbound, f"brachycal {shlex.join(argv)}: no example for {', '.join(unbound)} (START_BINDINGS)"
    return words


def test_the_start_list_names_every_command_group_in_its_current_spelling():
    """Each start-list form parses (its placeholders bound to the examples, or as written where the slow
    test below does not run it) with no note of an earlier spelling; together they name every command."""
    forms = [argv for line in start_list() for argv in _variants(line)]
    assert len(forms) >= 20  # a parser finding far fewer is broken
    for form in forms:
        argv = form if _not_run(form) else _bound(form)  # every placeholder of a form run has an example
        err = io.StringIO()
        with redirect_stderr(err), redirect_stdout(io.StringIO()):
            joined = joined_command(argv)
            try:
                build_parser(full=(joined[0],)).parse_args(joined)
            except SystemExit as exc:
                err.write(f"exit {exc.code}")
        assert err.getvalue() == "", f"brachycal {shlex.join(argv)}: {err.getvalue()}"
    named = {joined_command(argv)[0].split("-")[0] for argv in forms}
    assert named == {name.split("-")[0] for name in COMMANDS}


@pytest.mark.slow
def test_every_start_list_command_runs_on_the_bundled_data(tmp_path, monkeypatch):
    """``brachycal --help``'s start list, each form with its placeholders bound to the example files
    (:data:`START_BINDINGS`), in order in one folder after :data:`START_SETUP`."""
    monkeypatch.chdir(tmp_path)
    ran: list[list[str]] = []
    failures: list[str] = []
    forms = [form for line in start_list() for form in _variants(line) if not _not_run(form)]
    for argv in [*START_SETUP, *map(_bound, forms)]:
        if argv in ran:
            continue
        ran.append(argv)
        if argv[0] == "view":
            _serves(argv, tmp_path)
            continue
        code, err = _run(argv)
        if code != 0:
            failures.append(f"brachycal {shlex.join(argv)} -> exit {code}: {err.strip()}")
    assert not failures, "\n".join(failures)
    assert len(ran) >= 20


def _serves(argv: list[str], cwd: Path) -> None:
    """Start ``brachycal view …`` (on a free port), wait for its address, stop it with SIGTERM."""
    process = subprocess.Popen(
        [sys.executable, "-m", "brachycal.cli.main", *argv, "--port", "0"],
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    # A view that hangs before serving is killed (then its address never comes and the test fails).
    watchdog = threading.Timer(120, process.kill)
    watchdog.start()
    try:
        # viser prints its own banner first; the command's address line follows it.
        lines = iter(process.stdout.readline, "") if process.stdout else iter(())
        address = next((line for line in lines if line.startswith("brachycal view: ")), "")
        assert address.startswith("brachycal view: http"), f"brachycal {shlex.join(argv)} printed no address"
    finally:
        watchdog.cancel()
        process.send_signal(signal.SIGTERM)
        _, err = process.communicate(timeout=60)
    # SIGTERM: the command's own one-line "terminated", exit 143 (cli/main.py), no traceback.
    assert process.returncode == 143, err
    assert "Traceback" not in err


@pytest.mark.parametrize("argv", [["view", "--robot", "nonexistent"]])
def test_a_view_that_cannot_start_is_not_taken_for_serving(argv, tmp_path):
    """The check above can fail: a view that refuses does not print an address."""
    with pytest.raises(AssertionError):
        _serves(argv, tmp_path)


# --- the README's tour, as a newcomer runs it, twice, in a fresh clone -----------------------------


#: The tour's result file and the Python example's (another session's): two files.
PYTHON_AND_TOUR = ("result.json", "exact_result.json")


def fenced_blocks(text: str, language: str) -> list[str]:
    """The bodies of the ````` ```language ````` blocks of a Markdown ``text``, as written."""
    return re.findall(rf"^```{language}\n(.*?)^```", text, flags=re.MULTILINE | re.DOTALL)


def tour_blocks(readme: Path) -> tuple[str, str]:
    """The ```sh and the ```python block of the README's tour section (its ``## `` heading with
    "tour" to the next ``## ``): what a newcomer types, in the shell and in Python."""
    sections = re.split(r"^## ", readme.read_text(), flags=re.MULTILINE)
    tour = next(section for section in sections if section.split("\n", 1)[0].lower().count("tour"))
    (shell,), (python,) = fenced_blocks(tour, "sh"), fenced_blocks(tour, "python")
    return shell, python


def make_demo_command(makefile: Path) -> list[str]:
    """The ``brachycal`` command of ``make demo``'s recipe (its first line; ``$(BIN)/`` dropped)."""
    recipe = re.search(r"^demo:.*\n\t\$\(BIN\)/brachycal (.*)$", makefile.read_text(), flags=re.MULTILINE)
    assert recipe, "make demo does not run $(BIN)/brachycal first"
    return shlex.split(recipe.group(1), comments=True)


def test_the_tour_is_found_in_the_readme():
    """The parser finds the tour as the README shows it (a broken parser must not pass by finding nothing)."""
    shell, python = tour_blocks(ROOT / "README.md")
    assert shell.splitlines()[0].startswith("mkdir -p ~/") and "brachycal session build" in shell
    assert "brachycal.write_result(" in python and "force=True" in python
    assert make_demo_command(ROOT / "Makefile")[0] == "demo"


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("git") is None or not (ROOT / ".git").exists(), reason="needs git and a clone")
def test_the_readme_tour_runs_twice_after_make_demo_in_a_fresh_clone_and_leaves_it_clean(tmp_path):
    """A fresh clone of HEAD: ``make demo``'s command in its root, then the README's tour (its ```sh
    block, through bash, ``brachycal`` on PATH) and its Python example, twice in a row, then ``make
    demo`` again; each exits 0 and the clone holds nothing git does not ignore afterwards.

    brachycal is the installed one with the clone's ``src`` first on ``PYTHONPATH`` (no new venv);
    ``HOME`` is a folder of the test's, so the tour's ``~/…`` folder is too.
    """
    clone, home, bin_dir = tmp_path / "clone", tmp_path / "home", tmp_path / "bin"
    subprocess.run(["git", "clone", "--quiet", str(ROOT), str(clone)], check=True, capture_output=True)
    home.mkdir()
    bin_dir.mkdir()
    for name, run in (("brachycal", "-m brachycal.cli.main "), ("python", "")):  # this Python, as a venv's
        (bin_dir / name).write_text(f'#!/bin/sh\nexec "{sys.executable}" {run}"$@"\n')
        (bin_dir / name).chmod(0o755)
    env = {
        **os.environ,
        "HOME": str(home),
        "PATH": f"{bin_dir}{os.pathsep}{os.environ.get('PATH', '')}",
        "PYTHONPATH": str(clone / "src"),
    }
    shell, python = tour_blocks(clone / "README.md")
    # The Python example runs where the tour's commands left the shell (its folder).
    walk = f"set -e\n{shell}\npython - <<'BRACHYCAL_PYTHON'\n{python}BRACHYCAL_PYTHON\n"
    demo = ["brachycal", *make_demo_command(clone / "Makefile")]
    for step, command in [("make demo", demo), ("tour", ["bash", "-c", walk]), ("tour again", ["bash", "-c", walk])]:
        done = subprocess.run(command, cwd=clone, env=env, capture_output=True, text=True, check=False)
        assert done.returncode == 0, f"{step}: exit {done.returncode}\n{done.stderr[-3000:]}"
        assert "Traceback" not in done.stderr, f"{step}:\n{done.stderr[-3000:]}"
    # make demo after the tour, too: neither collides with the other.
    assert subprocess.run(demo, cwd=clone, env=env, capture_output=True, check=False).returncode == 0
    status = subprocess.run(["git", "status", "--porcelain"], cwd=clone, capture_output=True, text=True, check=True)
    assert status.stdout == "", f"the clone is not clean after the tour:\n{status.stdout}"
    tour = home / "brachycal-tour"
    assert (tour / "result.json").is_file() and (tour / "sda10f_calibrated.urdf").is_file()
    assert all((tour / name).is_file() for name in PYTHON_AND_TOUR)
    # The Python example's result is its own (the exact session's), not the tour's, which it leaves be.
    tour_inputs, python_inputs = (brachycal.read_result(tour / name).raw["inputs"] for name in PYTHON_AND_TOUR)
    assert tour_inputs != python_inputs
    assert (tour / "exports").is_dir() and (clone / "demo_output" / "result.json").is_file()
