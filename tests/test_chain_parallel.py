"""Refits shared between cores: the same answers and the same leave-one-out as in turn.

:func:`~brachycal.calibration.parallel.parallel_map` forks workers on Linux; everything it computes
must be what one process computes, and a worker's failure must look like the same failure in turn.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import warnings

import numpy as np
import pytest

import brachycal.calibration.parallel as parallel
from brachycal.calibration import calibrate
from brachycal.calibration.chain import cross_validate, fit_chain, select_model
from brachycal.calibration.parallel import available_workers, can_fork, forking_workers, parallel_map
from brachycal.errors import ConditioningWarning, DegenerateDataError
from brachycal.simulation.twin import TwinConfig, simulate


@pytest.fixture(scope="module")
def twin(robot):
    twin = simulate(robot, TwinConfig(seed=0))
    return twin.session, calibrate(twin.session, robot)


def _square(k: int) -> int:
    return k * k


def test_parallel_map_gives_what_a_loop_gives_in_order():
    assert parallel_map(_square, range(7), workers=3) == [k * k for k in range(7)]
    assert parallel_map(_square, [], workers=2) == []


def test_the_lowest_failing_item_raises_as_in_turn():
    def fn(k: int) -> int:
        if k in (3, 4):  # items 3 and 4 sit in different workers of two
            raise DegenerateDataError(f"item {k}", file="samples.csv")
        return k

    with pytest.raises(DegenerateDataError, match="item 3") as caught:
        parallel_map(fn, range(6), workers=2)
    assert caught.value.file == "samples.csv"  # the refusal keeps its parts across the pipe


def test_a_workers_warnings_are_issued_here():
    def fn(k: int) -> int:
        warnings.warn(f"grey zone {k}", ConditioningWarning, stacklevel=2)
        return k

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        parallel_map(fn, range(4), workers=2)
    assert sorted(str(w.message) for w in caught) == [f"grey zone {k}" for k in range(4)]
    assert all(w.category is ConditioningWarning for w in caught)


def test_a_worker_that_dies_has_its_items_computed_here():
    parent = os.getpid()

    def fn(k: int) -> int:
        if os.getpid() != parent:
            os._exit(3)  # dies without an answer
        return k + 1

    assert parallel_map(fn, range(5), workers=2) == [1, 2, 3, 4, 5]


def test_sequential_methods_on_two_cores_are_the_same_as_in_turn(robot, twin, monkeypatch):
    session, alone = twin  # a library call: in turn, in this process
    forks: list[int] = []
    fork = os.fork
    monkeypatch.setattr(os, "fork", lambda: forks.append(1) or fork())
    # Earlier tests of this process may leave threads behind (a viewer's server, a writer thread), which
    # keep parallel_map from forking; a command line's process has none. Their presence does not touch
    # what is compared here (the arithmetic in another process), so count them out for this check.
    monkeypatch.setattr(parallel.threading, "active_count", lambda: 1)
    assert can_fork(), "this check needs CPython 3.11 on Linux, where the command line forks"
    with forking_workers(2):  # what `brachycal calibrate` allows
        shared = calibrate(session, robot)
    assert forks, "the methods were not shared between two processes"
    for method, stats in alone.loocv.items():
        # Bit for bit: the same arithmetic on the same data, only in another process.
        assert np.array_equal(stats.errors_m, shared.loocv[method].errors_m), method
        assert np.array_equal(alone.image[method].T_Ptip_I, shared.image[method].T_Ptip_I), method


def test_a_library_call_does_not_fork_unless_asked(robot, twin, monkeypatch):
    """A notebook's or a thread pool's process is not forked behind its back: only the command line
    (forking_workers) or an explicit ``workers`` shares the work."""
    session, _ = twin
    monkeypatch.setattr(os, "fork", lambda: pytest.fail("forked without being asked"))
    assert available_workers() == 1
    calibrate(session, robot)


def test_model_choice_on_two_cores_is_the_same_as_in_turn(robot, twin):
    session, result = twin
    shared = select_model(session, robot, result, workers=2)
    alone = select_model(session, robot, result, workers=1)
    assert shared.model == alone.model and shared.undetermined == alone.undetermined
    for model, stats in alone.cv.items():
        assert np.array_equal(stats.errors_m, shared.cv[model].errors_m), model  # each CV is one run, shared or not


def test_leave_one_out_in_runs_agrees_with_one_run_of_all_folds(robot, twin):
    """Leave-one-out in runs of at most 32 warm-started folds (two cores share them) against the
    previous algorithm, one run of all 64 folds each starting from the previous fold's fit.

    The folds converge to the same fits from either start; what differs is where the noise levels'
    fixed-point iteration stops (relative change below 1e-6: a level ~1e-8 off its fixed point),
    which moves a fold's error by up to ~3e-8 mm with where the fold starts (measured on the example
    session and twin seed 0, both models that scale the depth: the previous algorithm itself is off
    its tightly settled fixed point by that much). Bounds: per sample 5e-8 mm, Table II's figures
    (means or the largest of 64) 3e-9 mm, far below the 0.01 mm the tables print."""
    session, result = twin
    model = "scaled_uv"
    fit = fit_chain(session, robot, result, model)
    n = len(session.uv_px)
    runs = cross_validate(session, robot, result, model, folds=n, start=fit, workers=2)
    runs_alone = cross_validate(session, robot, result, model, folds=n, start=fit, workers=1)
    before = cross_validate(session, robot, result, model, folds=n, start=fit, folds_per_run=None, workers=1)
    assert np.array_equal(runs.errors_m, runs_alone.errors_m)  # the runs do not depend on the cores
    assert np.abs(runs.errors_m - before.errors_m).max() * 1e3 < 5e-8
    for figure in ("mae_mm", "rmse_mm", "sd_mm", "max_mm"):
        assert abs(getattr(runs, figure) - getattr(before, figure)) < 3e-9, figure


def test_landing_jacobian_is_scipys_forward_difference_bit_for_bit(robot, twin):
    """The landing Jacobian's forward differences (written out so that ``calibrate`` need not import
    ``scipy.optimize``) are SciPy's ``approx_fprime`` with the same steps, to the last bit."""
    from scipy.optimize import approx_fprime

    from brachycal.calibration.chain import finite_difference_steps
    from brachycal.calibration.chain.uncertainty import _landing, landing_jacobian

    session, result = twin
    fit = fit_chain(session, robot, result, "sound_speed")
    q, uv = session.samples_q[:5], session.uv_px[:5]
    ours = landing_jacobian(fit, robot, session.spacing_m, q, uv)

    def landing(x):
        return _landing(x, fit, session.spacing_m, robot, q, uv).ravel()

    scipys = approx_fprime(fit.x, landing, finite_difference_steps(fit.x)).reshape(ours.shape)
    assert np.array_equal(ours, scipys)


def test_balanced_groups_place_the_costliest_first_into_the_cheapest_group():
    from brachycal.calibration.parallel import balanced_groups

    groups = balanced_groups([3.0, 1.0, 1.0, 1.0, 2.0], 2)
    assert sorted(k for g in groups for k in g) == [0, 1, 2, 3, 4]  # every call once
    assert sorted(sum([3.0, 1.0, 1.0, 1.0, 2.0][k] for k in g) for g in groups) == [4.0, 4.0]
    assert all(g == sorted(g) for g in groups)  # in index order within a group, as in turn
    assert balanced_groups([1.0, 1.0], 5) == [[0], [1]] and balanced_groups([], 2) == []


def test_parallel_calls_give_what_calls_in_turn_give_and_the_lowest_failure():
    from brachycal.calibration.parallel import parallel_calls

    calls = [lambda k=k: k * k for k in range(6)]
    assert parallel_calls(calls, [5.0, 1.0, 1.0, 1.0, 1.0, 1.0], workers=2) == [k * k for k in range(6)]

    def failing(k: int) -> int:
        if k in (1, 4):
            raise DegenerateDataError(f"call {k}", file="samples.csv")
        return k

    # Costs put call 4 first in the parent's group and call 1 in the worker's: the lowest still wins.
    with pytest.raises(DegenerateDataError, match="call 1"):
        parallel_calls([lambda k=k: failing(k) for k in range(6)], [1.0, 1.0, 1.0, 1.0, 9.0, 1.0], workers=2)
    with pytest.raises(ValueError, match="costs"):
        parallel_calls(calls, [1.0], workers=2)


def test_calibrating_a_folder_on_two_cores_is_the_same_as_in_turn(robot, monkeypatch):
    """``calibrate --solve chain``'s path: the sequential method's leave-one-out and the chain's model
    choice share the cores, then the chain's leave-one-out and predicted landing errors do; every
    figure is the same arithmetic as in turn, bit for bit."""
    from pathlib import Path

    from brachycal.calibration import calibrate_folder

    folder = Path(__file__).resolve().parents[1] / "examples" / "twin_session"
    alone = calibrate_folder(folder, robot, chain=True)  # a library call: in turn
    monkeypatch.setattr(parallel.threading, "active_count", lambda: 1)  # as in the test above
    forks: list[int] = []
    fork = os.fork
    monkeypatch.setattr(os, "fork", lambda: forks.append(1) or fork())
    with forking_workers(2):
        shared = calibrate_folder(folder, robot, chain=True)
    assert forks, "nothing was shared between two processes"
    for method, stats in alone.result.loocv.items():
        assert np.array_equal(stats.errors_m, shared.result.loocv[method].errors_m), method
        assert np.array_equal(alone.result.image[method].T_Ptip_I, shared.result.image[method].T_Ptip_I), method
    assert alone.chain is not None and shared.chain is not None
    assert alone.chain.choice.model == shared.chain.choice.model
    for model, stats in alone.chain.choice.cv.items():
        assert np.array_equal(stats.errors_m, shared.chain.choice.cv[model].errors_m), model
    assert np.array_equal(alone.chain.fit.x, shared.chain.fit.x)
    assert np.array_equal(alone.chain.loocv.errors_m, shared.chain.loocv.errors_m)
    assert np.array_equal(alone.chain.predicted_cube_mm, shared.chain.predicted_cube_mm)
    assert np.array_equal(alone.chain.predicted_fov_mm, shared.chain.predicted_fov_mm)


def _in_a_fresh_interpreter(code: str) -> None:
    """Run ``code`` in a new Python process: the collector's state (enabled, frozen) is the process's, so
    a test of it must not see what other tests (or their leftover threads) did to this one's."""
    result = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr


def test_frozen_heap_and_the_command_leave_the_collector_as_they_found_it(tmp_path):
    """The command line disables the collector while it imports and freezes the long-lived objects while
    it computes (forked workers then share their pages); a refusal or a library call leaves neither behind."""
    _in_a_fresh_interpreter(
        f"""
        import contextlib, gc, io

        from brachycal.calibration.parallel import frozen_heap
        from brachycal.cli.main import main

        assert gc.get_freeze_count() == 0
        with frozen_heap():
            assert gc.get_freeze_count() > 0
        assert gc.get_freeze_count() == 0
        for enabled in (True, False):
            (gc.enable if enabled else gc.disable)()
            with contextlib.redirect_stderr(io.StringIO()):  # refused after the imports, before any computation
                code = main(["calibrate", {str(tmp_path / "no_session")!r}, "--out", {str(tmp_path / "r.json")!r}])
            assert code == 2 and gc.isenabled() is enabled and gc.get_freeze_count() == 0, (code, enabled)
        """
    )


def test_frozen_heap_leaves_a_callers_own_freeze_alone():
    _in_a_fresh_interpreter(
        """
        import gc

        from brachycal.calibration.parallel import frozen_heap

        gc.freeze()
        with frozen_heap():
            pass
        assert gc.get_freeze_count() > 0  # the caller's freeze is not released by the command's exit
        gc.unfreeze()
        with frozen_heap():
            assert gc.get_freeze_count() > 0
        assert gc.get_freeze_count() == 0
        """
    )
