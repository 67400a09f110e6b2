"""brachycal's fork pool (``parallel_calls``) beside the standard library's process pool, in one run.

Run: ``.venv/bin/python benchmarks/parallel_pool.py``. The work is the sequential method's
per-method fits with their leave-one-out (five methods) on the bundled exact session: in turn, with
``parallel_calls`` on two workers (forked workers inherit the prepared problem; only results come
back), and with ``concurrent.futures.ProcessPoolExecutor`` on two forked workers (each call, which
carries the prepared problem, is pickled to a worker). Prints the best and median of 5 runs each.
"""

import multiprocessing as mp
import pickle
import statistics
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from brachycal.calibration.labels import METHODS
from brachycal.calibration.parallel import forking_workers, parallel_calls
from brachycal.calibration.sequential.method import SequentialPlan
from brachycal.data.session import read_session
from brachycal.model import Robot

robot = Robot.load()
session = read_session(Path(__file__).parent.parent / "examples" / "session_exact", robot)
plan = SequentialPlan.prepare(session, robot, list(METHODS), None)
calls, costs = plan.calls()
print("calls", len(calls), "pickled call size", len(pickle.dumps(calls[0])), "bytes")


def call(c):
    return c()


def ours():
    with forking_workers(2):
        return parallel_calls(calls, costs, 2)


def ppe():
    with ProcessPoolExecutor(2, mp_context=mp.get_context("fork")) as ex:
        return list(ex.map(call, calls))


def serial():
    return [c() for c in calls]


for name, f in (("in turn", serial), ("parallel_calls", ours), ("ProcessPoolExecutor(fork)", ppe)):
    times = []
    for _ in range(5):
        start = time.perf_counter()
        f()
        times.append(time.perf_counter() - start)
    print(f"{name}: best {min(times) * 1e3:.0f} ms, median {statistics.median(times) * 1e3:.0f} ms")
