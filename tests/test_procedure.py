"""The procedure page is a lab's day that runs: plan, record, build the session, calibrate, verify,
the check before a procedure, export — on the twin's recordings, every command as the page shows it.

The commands are read from docs/procedure.md itself, so that the test breaks when the page drifts:
every ``brachycal`` line of its ```sh blocks (``\\`` continuations joined, ``# comments`` dropped)
must exit 0, and every ``$ brachycal`` line of a ```text block must exit as its ``# exit N`` says
and print first the word the page shows under it (the check's verdict). Each runs as a user runs
it, in a process of its own, in an empty folder; the whole page is walked twice in that folder,
since each command can be run again (``--force``).
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest
from conftest import ROOT

PAGE = ROOT / "docs" / "procedure.md"


@dataclass(frozen=True)
class Step:
    """One command of the page: ``argv`` without ``brachycal``, the exit it must give and the first
    word of the output the page shows for it (``""``: none shown)."""

    argv: list[str]
    code: int = 0
    shows: str = ""


def _joined(lines: list[str]) -> list[str]:
    """Lines with their ``\\`` continuations joined."""
    text = "\n".join(lines).replace("\\\n", " ")
    return [line.strip() for line in text.splitlines()]


def page_steps(path: Path) -> list[Step]:
    """The page's commands, in page order: ```sh lines (exit 0) and ```text ``$ `` lines."""
    steps: list[Step] = []
    kind: str | None = None
    block: list[str] = []
    for line in path.read_text().splitlines():
        fence = line.strip().startswith("```")
        if kind is None:
            kind, block = (line.strip()[3:].strip(), []) if fence else (None, [])
            continue
        if not fence:
            block.append(line)
            continue
        lines = _joined(block)
        for k, command in enumerate(lines):
            shown = kind == "text" and command.startswith("$ brachycal ")
            words = shlex.split(command[2:] if shown else command, comments=True) if kind == "sh" or shown else []
            if not words or words[0] != "brachycal":
                continue
            exit_code = re.search(r"#\s*exit (\d+)\s*$", command) if shown else None
            after = lines[k + 1].split() if shown and k + 1 < len(lines) else []
            steps.append(
                Step(words[1:], int(exit_code.group(1)) if exit_code else 0, after[0].rstrip(":") if after else "")
            )
        kind = None
    return steps


def _is(step: Step, *words: str) -> bool:
    return step.argv[: len(words)] == list(words)


#: The day's stages, in the page's order: a name and what its first command is.
STAGES: tuple[tuple[str, Callable[[Step], bool]], ...] = (
    ("plan", lambda s: _is(s, "plan", "--out")),
    ("record", lambda s: _is(s, "demo", "--recording")),
    ("build", lambda s: _is(s, "session", "build") and "--check" not in s.argv),
    ("calibrate", lambda s: _is(s, "calibrate")),
    ("check plan", lambda s: _is(s, "plan", "check")),
    ("check build", lambda s: _is(s, "session", "build") and "--check" in s.argv),
    ("check", lambda s: _is(s, "verify")),
    ("export", lambda s: _is(s, "export")),
)


def test_the_page_walks_the_day_with_its_check():
    """The page shows plan → record (with the check's recordings) → build → calibrate → the check (its
    session built from a check recording, one PASS, one RECALIBRATE) → export, in that order."""
    steps = page_steps(PAGE)
    first = [next((k for k, step in enumerate(steps) if found(step)), -1) for _, found in STAGES]
    named = dict(zip([name for name, _ in STAGES], first, strict=True))
    assert -1 not in first and first == sorted(first), named
    assert "--check" in steps[named["record"]].argv  # the twin records the check too
    verifies = [s for s in steps if _is(s, "verify")]
    assert [s for s in verifies if s.code == 0 and not s.shows], "a check that passes, in a ```sh block"
    assert [s for s in verifies if s.code == 1 and s.shows == "RECALIBRATE"], "a check that fails, with its verdict"


def _run(argv: list[str], folder: Path) -> tuple[int, str, str, float]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "src"), *filter(None, [env.get("PYTHONPATH")])])
    start = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-m", "brachycal.cli.main", *argv],
        cwd=folder,
        env=env,
        capture_output=True,
        text=True,
        timeout=1800,
        check=False,
    )
    return done.returncode, done.stdout, done.stderr, time.perf_counter() - start


@pytest.mark.slow
def test_the_procedure_page_runs_as_written_twice(tmp_path):
    """Every command of the page exits as the page says, in an empty folder, twice; the checks give
    PASS on the unchanged set-up and RECALIBRATE after the probe holder was remounted; the session
    commands, the check's plan and a failed check say the next step."""
    steps = page_steps(PAGE)
    assert len(steps) >= 12
    timings: list[str] = []
    for walk in (1, 2):
        for step in steps:
            code, out, err, seconds = _run(step.argv, tmp_path)
            timings.append(f"walk {walk}: {seconds:6.1f} s  brachycal {shlex.join(step.argv)}")
            said = f"brachycal {shlex.join(step.argv)} (walk {walk}) -> exit {code}: {err.strip()[-2000:]}"
            assert code == step.code, said
            if _is(step, "verify"):
                verdict = out.split()[0].rstrip(":") if out.split() else ""
                assert verdict == (step.shows or "PASS"), said + "\n" + out
            if _is(step, "session") or _is(step, "plan", "check") or (_is(step, "verify") and step.code):
                assert "\nnext: " in out, f"{said}: no next step said\n{out}"
    print("\n".join(timings))
