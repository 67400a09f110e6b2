"""Calibration speed on the 64-sample example session (``examples/twin_session``).

Run: ``.venv/bin/python benchmarks/calibrate_speed.py``. Figures:

- end to end, what a user waits for: ``brachycal calibrate examples/twin_session --solve chain``
  in a new process (start-up, imports, the sequential method, model choice by 8-fold
  cross-validation over 4 image models, the final fit with the robot term, leave-one-out over 64
  samples, predicted landing error, result file), no bootstrap, best of 3; recorded in
  ``benchmarks/results.json`` beside its peer, the same command with the sequential method alone
  (best of 3), against issue 13's goal :data:`GOAL_S`;
- start-up: a new process importing what the command imports before it computes (best of 3);
- in this process, the sequential method and the chain's stages (:func:`~brachycal.calibration.chain.select_model`, the
  final :func:`~brachycal.calibration.chain.fit_chain`, the leave-one-out
  :func:`~brachycal.calibration.chain.cross_validate`), best of 3, so that the end-to-end figure
  can be read as start-up + sequential + chain (+ reading the session and writing the result).

Cores: the command runs the sequential method's leave-one-out with the model choice's refits in
one forked stage, then the chain's leave-one-out runs with the landing-error maps in another
(:func:`brachycal.calibration.parallel.parallel_calls`, longest first; the figures are the same on
any number of cores). The stages printed here are the library calls run one after another, each
on all of this process's cores and, for comparison, on one: their sum is more than the command's
share of the end-to-end figure, where the stages overlap.

BLAS threads: on this 2-core machine the figures are measured as the command runs by default;
run with ``OMP_NUM_THREADS=1`` to compare (the problems are small: one thread is as fast).
"""

from __future__ import annotations

import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from timing import best_of, best_wall, brachycal_command, record

import brachycal.calibration.parallel as parallel
from brachycal.calibration import calibrate
from brachycal.calibration.chain import cross_validate, fit_chain, select_model
from brachycal.calibration.parallel import available_workers
from brachycal.data.session import read_session
from brachycal.model import Robot

SESSION = Path(__file__).resolve().parents[1] / "examples" / "twin_session"
#: Issue 13's goal for ``calibrate --solve chain`` end to end without bootstrap, seconds.
GOAL_S = 2.0


def end_to_end(method: str, repeats: int = 3) -> float:
    """Best wall time of ``brachycal calibrate`` on the example session with ``--method``, in a new
    process, seconds."""
    with tempfile.TemporaryDirectory() as tmp:
        argv = ["calibrate", str(SESSION), "--out", str(Path(tmp) / "r.json"), "--solve", method, "--force", "--quiet"]
        return best_wall([*brachycal_command(), *argv], repeats)


#: What ``calibrate --solve chain`` imports before it computes (the command line, the robot model, the
#: sequential method and the chain, the tables): timed in a new process as the start-up part of the end-to-end figure.
STARTUP_IMPORTS = (
    "import brachycal.cli.main, brachycal.cli.calibrate, brachycal.model, "
    "brachycal.calibration.session.calibrate, brachycal.reporting.tables"
)


def startup(repeats: int = 3) -> float:
    """Best wall time of a new Python process that only imports :data:`STARTUP_IMPORTS`, seconds."""
    return best_wall([sys.executable, "-c", STARTUP_IMPORTS], repeats)


def stages(repeats: int = 3) -> None:
    """Print the chain's stages timed in this process (best of ``repeats``), on all cores and on one."""
    robot = Robot.load()
    session = read_session(SESSION, robot)
    result = calibrate(session, robot)
    choice = select_model(session, robot, result)
    fit = fit_chain(session, robot, result, choice.model)
    n = len(session.uv_px)
    with parallel.forking_workers():  # as `brachycal calibrate` allows (a library call runs in turn)
        cores = available_workers()
    print(f"new process, imports only (best of {repeats}): {startup(repeats):.2f} s")
    print(f"in process, {n} samples (best of {repeats}; {cores} cores | 1 core):")
    for name, run in {
        "sequential method (Tables I and II)": lambda w: calibrate(session, robot),
        "chain: model choice (4 models x 8 folds)": lambda w: select_model(session, robot, result, workers=w),
        "chain: final fit with the robot term": lambda w: fit_chain(session, robot, result, choice.model),
        f"chain: leave-one-out ({n} refits)": lambda w: cross_validate(
            session, robot, result, choice.model, folds=n, start=fit, workers=w
        ),
    }.items():
        with parallel.forking_workers():
            shared = best_of(repeats, lambda run=run: run(None))
        with _one_core():
            alone = best_of(repeats, lambda run=run: run(1))
        print(f"  {name:<45} {shared:6.2f} s | {alone:6.2f} s")


@contextmanager
def _one_core() -> Iterator[None]:
    """Everything :func:`~brachycal.calibration.parallel.parallel_map` runs, in this process alone."""
    saved = parallel.can_fork
    parallel.can_fork = lambda: False
    try:
        yield
    finally:
        parallel.can_fork = saved


def main() -> None:
    stages()
    sequential = end_to_end("sequential")
    chain = end_to_end("chain")
    record(
        "calibrate: brachycal calibrate --solve chain (64 samples) end to end",
        chain,
        "s",
        goal=f"<= {GOAL_S} s",
        met=chain <= GOAL_S,
        peer="the sequential method alone (same command, --solve sequential)",
        peer_value=sequential,
    )


if __name__ == "__main__":
    main()
