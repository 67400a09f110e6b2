"""Start-up of the command line: ``brachycal --help`` and each sub-command's ``--help``, as a user runs them.

Run: ``.venv/bin/python benchmarks/startup.py``. Each figure is the best of 5 runs of a fresh
process (the least disturbed run: other work on the machine only adds time), beside the peer
every Python program pays, ``python -c pass``. Goal (issue 13): ``brachycal --help`` within
0.35 s; a sub-command imports only what it uses, so its ``--help`` loads none of Pinocchio,
SciPy, mink or matplotlib (listed per sub-command when it does).
"""

from __future__ import annotations

import subprocess
import sys

from timing import best_wall, brachycal_command, record

from brachycal.cli.main import COMMANDS

#: Goal of ``brachycal --help``, seconds (issue 13).
GOAL_S = 0.35
#: The libraries a ``--help`` should not need (each takes 0.1-0.5 s to import).
HEAVY = ("pinocchio", "scipy", "mink", "matplotlib")
REPEATS = 5


def heavy_imports(words: list[str]) -> list[str]:
    """Which of :data:`HEAVY` ``brachycal <words>`` imports (run in a new process)."""
    probe = (
        "import contextlib, io, sys\n"
        "from brachycal.cli.main import main\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        f"    main({words!r})\n"
        f"print(' '.join(m for m in {HEAVY!r} if m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", probe], check=True, capture_output=True, text=True).stdout
    return out.split()


def main() -> None:
    peer = best_wall([sys.executable, "-c", "pass"], REPEATS)
    command = brachycal_command()
    every = [["--help"]] + [[name, "build", "--help"] if name == "session" else [name, "--help"] for name in COMMANDS]
    for words in every:
        value = best_wall([*command, *words], REPEATS)
        loaded = heavy_imports(words)
        record(
            f"startup: brachycal {' '.join(words)}",
            value,
            "s",
            goal=f"<= {GOAL_S} s, no {'/'.join(HEAVY)}" + (f" (loads {', '.join(loaded)})" if loaded else ""),
            met=value <= GOAL_S and not loaded,
            peer="python -c pass",
            peer_value=peer,
        )


if __name__ == "__main__":
    main()
