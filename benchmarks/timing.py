"""Timing helpers shared by the benchmark scripts, and the one writer of ``benchmarks/results.json``."""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

RESULTS = Path(__file__).with_name("results.json")


def best_of(repeats: int, fn: Callable[[], object]) -> float:
    """Shortest wall time of ``repeats`` calls, seconds (the least disturbed run)."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def brachycal_command() -> list[str]:
    """The installed ``brachycal`` script next to this Python, else ``python -m brachycal.cli.main``."""
    script = Path(sys.executable).with_name("brachycal")
    return [str(script)] if script.exists() else [sys.executable, "-m", "brachycal.cli.main"]


def best_wall(argv: list[str], repeats: int = 3) -> float:
    """Shortest wall time of ``repeats`` runs of ``argv`` in a new process each, seconds (start-up included)."""
    return best_of(repeats, lambda: subprocess.run(argv, check=True, stdout=subprocess.DEVNULL))


def machine() -> dict[str, object]:
    """What the figures were measured on (quoted beside them in docs/validation.md)."""
    return {
        "cpu": platform.processor() or platform.machine(),
        "cores": os.cpu_count(),
        "python": platform.python_version(),
    }


def record(
    figure: str,
    value: float,
    unit: str,
    *,
    goal: str,
    met: bool,
    peer: str | None = None,
    peer_value: float | None = None,
) -> None:
    """Print one figure beside its peer and goal, and merge it into :data:`RESULTS` under ``figure``.

    ``value``/``peer_value`` are in ``unit`` (e.g. ``"s"``, ``"MB"``); ``goal`` says the target in
    words (e.g. ``"<= 0.2 x the plain loop"``) and ``met`` whether this run meets it.
    """
    line = f"{figure}: {value:.3g} {unit}"
    if peer is not None and peer_value is not None:
        line += f"  (peer: {peer} {peer_value:.3g} {unit}; ratio {value / peer_value:.2f})"
    print(f"{line}  goal {goal}: {'met' if met else 'NOT MET'}", flush=True)
    results = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
    results.setdefault("figures", {})[figure] = {
        "value": value,
        "unit": unit,
        "peer": peer,
        "peer_value": peer_value,
        "goal": goal,
        "met": bool(met),
        "measured": time.strftime("%Y-%m-%d"),
    }
    results["machine"] = machine()
    tmp = RESULTS.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(results, indent=2, sort_keys=True) + "\n")
    tmp.replace(RESULTS)
