"""Parameter studies on the twin: how the truth error and the LOO figures change with the set-up.

One run = one simulated session (a seed and a set of parameters) calibrated with the chosen
methods, judged by leave-one-out (what a lab sees) and by the end-to-end targeting error against
the truth (what the clinic needs). Runs are independent pure functions of their parameters, so
they can go to local processes or to a Dask cluster, and the rows come back in the same order
with the same numbers as a serial run.

Any robot (``RunParams.robot``: a bundled description's name or a description file every worker
can read): the twin plans in that robot's workspace. The held-out targeting figures turn the
torso (:mod:`brachycal.studies.targeting`); on a robot without a joint shared by both arms
they are NaN (no such turn exists).
"""

from __future__ import annotations

import itertools
import os
import socket
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, replace

import numpy as np

from brachycal.calibration import calibrate
from brachycal.calibration.chain import RobotAccuracy, cross_validate, fit_chain, select_model
from brachycal.calibration.result import Calibration
from brachycal.calibration.robot.identification import (
    IDENTIFICATION_FOLDS,
    choose_and_identify,
    cross_validate_identification,
)
from brachycal.calibration.sequential.image_to_probe import METHODS
from brachycal.calibration.sequential.method import SequentialResult
from brachycal.errors import DegenerateDataError, InputError
from brachycal.model.description import load_description
from brachycal.model.robot import Robot
from brachycal.planning.spec import EDGE_RANGE_M
from brachycal.simulation.settings import (
    HELD_OUT_TORSO_TURN_RAD,
    MAX_STUDY_RUNS,
    ROBOT_ERROR_LEVELS,
    STUDY_METHODS,
)
from brachycal.simulation.twin import MAX_ANNOTATION_SD_PX, MAX_OUTLIER_RATE, Twin, TwinConfig, simulate, spec_for
from brachycal.studies.targeting import targeting_error, torso_index
from brachycal.validate import (
    MAX_GRID_POINTS,
    MAX_SEEDS,
    MAX_TARGETS,
    MAX_WORKERS,
    check_int,
    check_probability,
    check_range,
    check_seed,
)


@dataclass(frozen=True)
class RunParams:
    """Parameters of one run (all plain values, so runs can be shipped to other processes).

    Checked on construction, so a bad sweep is refused before any run starts: seed in [0, 2**32),
    points per axis in [2, 20], edge in [1, 500] mm, annotation noise in [0, 50] px, outlier rate
    in [0, 0.5], methods among :data:`STUDY_METHODS` (at least one), targets in [1, 100000];
    ``robot`` a robot description (a bundled name or a ``.toml`` path: loaded by each run).

    Raises:
        InputError: naming the parameter, its range and the value given.
    """

    seed: int
    points_per_axis: int
    edge_mm: float
    annotation_px: float
    sound_speed: bool
    outlier_rate: float
    methods: tuple[str, ...]
    targets: int
    robot_error: str = "well-built"
    robot: str = "sda10f"

    def __post_init__(self) -> None:
        check_seed(self.seed, "seed")
        check_int(self.points_per_axis, "points per axis", low=2, high=MAX_GRID_POINTS)
        check_range(self.edge_mm, "cube edge", low=EDGE_RANGE_M[0] * 1e3, high=EDGE_RANGE_M[1] * 1e3, unit="mm")
        check_range(self.annotation_px, "annotation noise", low=0.0, high=MAX_ANNOTATION_SD_PX, unit="px")
        if not isinstance(self.sound_speed, (bool, np.bool_)):
            raise InputError(f"sound_speed must be True or False, got {self.sound_speed!r}")
        check_probability(self.outlier_rate, "outlier rate", high=MAX_OUTLIER_RATE)
        unknown = [m for m in self.methods if m not in STUDY_METHODS]
        if not self.methods or unknown or isinstance(self.methods, str):
            raise InputError(f"methods must be a tuple of {', '.join(STUDY_METHODS)}, got {self.methods!r}")
        check_int(self.targets, "targets", low=1, high=MAX_TARGETS)
        if self.robot_error not in ROBOT_ERROR_LEVELS:
            raise InputError(
                f"unknown robot-error level {self.robot_error!r}; choose from {', '.join(ROBOT_ERROR_LEVELS)}"
            )
        if not isinstance(self.robot, str) or not self.robot:
            raise InputError(f"robot must be a robot description's name or file, got {self.robot!r}")


def sweep(
    seeds: int,
    points: Sequence[int],
    edges_mm: Sequence[float],
    annotation_px: Sequence[float],
    sound_speed: Sequence[bool] = (True,),
    outlier_rates: Sequence[float] = (0.0,),
    methods: tuple[str, ...] = ("kabsch", "scaled_uv"),
    targets: int = 30,
    robot_errors: Sequence[str] = ("well-built",),
    robot: str = "sda10f",
) -> list[RunParams]:
    """Every combination, seeds innermost (the order rows are reported in).

    ``seeds`` is a count in [1, 1000]; each list needs at least one value; the sweep has at most
    :data:`MAX_STUDY_RUNS` runs; every run's parameters are checked (:class:`RunParams`) before
    this returns.

    Raises:
        InputError: a count or a value out of range, or an empty list.
    """
    check_int(seeds, "seeds", low=1, high=MAX_SEEDS)
    for name, values in (
        ("points", points),
        ("edges", edges_mm),
        ("annotation noises", annotation_px),
        ("sound speeds", sound_speed),
        ("outlier rates", outlier_rates),
        ("robot-error levels", robot_errors),
    ):
        if len(values) == 0:
            raise InputError(f"the list of {name} is empty")
    total = (
        seeds
        * len(points)
        * len(edges_mm)
        * len(annotation_px)
        * len(sound_speed)
        * len(outlier_rates)
        * len(robot_errors)
    )
    if total > MAX_STUDY_RUNS:
        raise InputError(
            f"the sweep has {total} simulated sessions (seeds x every combination); at most {MAX_STUDY_RUNS} "
            "(each takes seconds to minutes): sweep fewer values or seeds"
        )
    combos = itertools.product(robot_errors, points, edges_mm, annotation_px, sound_speed, outlier_rates, range(seeds))
    return [RunParams(seed, p, e, a, s, o, methods, targets, level, robot) for level, p, e, a, s, o, seed in combos]


def load_study_robot(name: str) -> Robot:
    """The nominal robot of a run: the bundled SDA10F as :meth:`Robot.load` gives it, any other a description."""
    if name == "sda10f":
        return Robot.load()

    return load_description(name).robot


def run_one(params: RunParams) -> list[dict[str, object]]:
    """Simulate, calibrate and judge one session; one row per method (a method that refuses the
    session is a row saying why, ``refused``, with NaN figures; every method refusing, all rows)."""
    robot = load_study_robot(params.robot)
    base = TwinConfig().with_robot_error(params.robot_error)
    config = replace(
        base,
        seed=params.seed,
        annotation_sd_px=params.annotation_px,
        sound_speed=params.sound_speed,
        outliers=params.outlier_rate > 0,
        outlier_rate=params.outlier_rate,
        spec=replace(spec_for(robot, base), points_per_axis=params.points_per_axis, edge_m=params.edge_mm * 1e-3),
    )
    twin = simulate(robot, config)
    sequential = tuple(m for m in params.methods if m in METHODS)
    result: SequentialResult | None = None
    refusal = ""
    try:
        result = calibrate(twin.session, robot, sequential or ("scaled_uv",))
    except DegenerateDataError as exc:  # every method (or a tool) refuses this session: each row says why
        refusal = str(exc)
    rows = []
    for method in params.methods:
        if result is None or method in result.refused:  # a finding, not a crash
            figures: dict[str, object] = {"refused": refusal if result is None else result.refused[method]}
        else:
            try:
                figures = _judge(twin, robot, result, method, params.targets)
            except DegenerateDataError as exc:  # the method refuses this session: a finding, not a crash
                figures = {"refused": exc.problem}
        rows.append(
            {
                **{k: v for k, v in asdict(params).items() if k != "methods"},
                "samples": len(twin.session.sample_ids),
                "method": method,
                **{key: figures.get(key, np.nan) for key in FIGURES},
                "chain_model": figures.get("chain_model", ""),
                "refused": figures.get("refused", ""),
                "table1_needle_mae_mm": result.needle.validation.mae_mm if result else np.nan,
                "table1_probe_mae_mm": result.probe.validation.mae_mm if result else np.nan,
            }
        )
    return rows


#: The figures of one method on one session (NaN where the method refused the session).
FIGURES = (
    "cv_folds",
    "loo_mae_mm",
    "loo_rmse_mm",
    "loo_sd_mm",
    "loo_max_mm",
    "target_mae_mm",
    "target_rmse_mm",
    "target_sd_mm",
    "target_max_mm",
    "target_held_out_mae_mm",
    "target_held_out_max_mm",
    "needle_tip_error_mm",
)


def _judge(twin: Twin, robot: Robot, result: SequentialResult, method: str, targets: int) -> dict[str, object]:
    """One method's calibration of the twin's session and its figures (:data:`FIGURES`)."""
    session, software = twin.session, robot
    n, chosen = len(session.uv_px), ""
    if method == "chain":
        chosen = select_model(session, robot, result).model
        fit = fit_chain(session, robot, result, chosen, robot_accuracy=None)
        loo = cross_validate(session, robot, result, chosen, folds=n)
    if method == "chain+robot":  # K-fold over configurations: every fold identifies the robot again
        config = twin.config
        accuracy = RobotAccuracy(config.link_offset_sd_m, config.link_tilt_sd_rad, config.encoder_sd_rad)
        choice, identified = choose_and_identify(session, robot, result, accuracy)
        chosen = choice.model
        fit, software, n = identified.fit, identified.robot(robot), IDENTIFICATION_FOLDS
        loo = cross_validate_identification(session, robot, result, chosen, accuracy)[1]
    if method in ("chain", "chain+robot"):
        T_ER_Ntip, T_EL_Ptip, image = fit.T_ER_Ntip, fit.T_EL_Ptip, fit.image
    else:
        T_ER_Ntip, T_EL_Ptip, image = result.T_ER_Ntip, result.T_EL_Ptip, result.image[method]
        loo = result.loocv[method]
    hit = targeting_error(twin, Calibration(T_ER_Ntip, T_EL_Ptip, image), targets, software=software).stats
    if torso_index(robot) is None:  # no torso to turn: no held-out configurations (NaN, module docstring)
        held_out_mae_mm = held_out_max_mm = float("nan")
    else:
        held_out = targeting_error(
            twin,
            Calibration(T_ER_Ntip, T_EL_Ptip, image),
            targets,
            software=software,
            torso_turn_rad=HELD_OUT_TORSO_TURN_RAD,
        ).stats
        held_out_mae_mm, held_out_max_mm = held_out.mae_mm, held_out.max_mm
    return {
        "chain_model": chosen,
        "cv_folds": n,
        "loo_mae_mm": loo.mae_mm,
        "loo_rmse_mm": loo.rmse_mm,
        "loo_sd_mm": loo.sd_mm,
        "loo_max_mm": loo.max_mm,
        "target_mae_mm": hit.mae_mm,
        "target_rmse_mm": hit.rmse_mm,
        "target_sd_mm": hit.sd_mm,
        "target_max_mm": hit.max_mm,
        "target_held_out_mae_mm": held_out_mae_mm,
        "target_held_out_max_mm": held_out_max_mm,
        "needle_tip_error_mm": float(np.linalg.norm(T_ER_Ntip[:3, 3] - twin.truth.T_ER_Ntip[:3, 3]) * 1e3),
    }


def run_study(
    runs: Sequence[RunParams],
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: Callable[[int], None] | None = None,
) -> list[dict[str, object]]:
    """Run every run; rows in the order of ``runs`` whatever executes them.

    Args:
        runs: from :func:`sweep`.
        workers: local processes (default: all cores; 1 runs serially in this process).
        scheduler: address of a Dask distributed scheduler (``tcp://host:8786``) to run on instead.
        progress: called with 1 as each run finishes.

    Raises:
        InputError: ``workers`` is not a whole number in [1, 256].
    """
    if workers is not None:
        check_int(workers, "workers", low=1, high=MAX_WORKERS)

    def tick(rows: list[dict[str, object]]) -> list[dict[str, object]]:
        if progress is not None:
            progress(1)
        return rows

    if scheduler is not None:
        results: Iterable[list[dict[str, object]]] = _dask_map(runs, scheduler, tick)
    elif workers == 1:
        results = [tick(run_one(r)) for r in runs]
    else:
        pool = ProcessPoolExecutor(max_workers=workers or os.cpu_count())
        try:
            results = [tick(rows) for rows in pool.map(run_one, runs)]
        except BaseException:
            # Interrupted (Ctrl-C, SIGTERM) or failed: drop the queued runs instead of finishing them.
            pool.shutdown(wait=False, cancel_futures=True)
            raise
        pool.shutdown()
    return [row for rows in results for row in rows]


def _dask_map(runs: Sequence[RunParams], scheduler: str, tick: Callable) -> list[list[dict[str, object]]]:
    try:
        from distributed import Client, as_completed  # lazy: start-up (distributed)
    except ImportError:
        raise InputError("--scheduler needs Dask: pip install 'brachycal[cluster]'") from None
    _check_reachable(scheduler)
    try:
        client = Client(scheduler, timeout=10)
    except (OSError, TimeoutError) as exc:
        raise InputError(f"cannot reach the Dask scheduler at {scheduler} ({exc})") from None
    with client:
        futures = client.map(run_one, runs, pure=False)
        index = {f.key: k for k, f in enumerate(futures)}
        out: list[list[dict[str, object]] | None] = [None] * len(runs)
        for future in as_completed(futures):
            out[index[future.key]] = tick(future.result())
    return [rows for rows in out if rows is not None]


def _check_reachable(scheduler: str) -> None:
    """Fail at once on a refused TCP address (Dask itself retries until its timeout)."""
    if not scheduler.startswith("tcp://"):
        return
    host, _, port = scheduler[len("tcp://") :].rpartition(":")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=3).close()
    except (OSError, ValueError) as exc:
        raise InputError(f"cannot reach the Dask scheduler at {scheduler} ({exc})") from None


def summarise(rows: Sequence[dict[str, object]]) -> list[dict[str, object]]:
    """Mean and SD over seeds for each parameter combination and method (sessions a method refused,
    as :class:`~brachycal.errors.DegenerateDataError`, are counted in ``refused`` and left out)."""
    keys = (
        "robot",
        "robot_error",
        "points_per_axis",
        "samples",
        "edge_mm",
        "annotation_px",
        "sound_speed",
        "outlier_rate",
        "method",
    )
    groups: dict[tuple, list[dict[str, object]]] = {}
    for row in rows:
        groups.setdefault(tuple(row[k] for k in keys), []).append(row)
    out = []
    for key, members in groups.items():
        entry: dict[str, object] = dict(zip(keys, key, strict=True))
        entry["seeds"] = len(members)
        entry["refused"] = sum(1 for m in members if m.get("refused"))
        for figure in (
            "loo_mae_mm",
            "loo_rmse_mm",
            "loo_sd_mm",
            "target_mae_mm",
            "target_rmse_mm",
            "target_max_mm",
            "target_held_out_mae_mm",
            "table1_needle_mae_mm",
            "table1_probe_mae_mm",
        ):
            values = np.array([m[figure] for m in members if not m.get("refused")], dtype=float)
            entry[f"{figure}_mean"] = float(values.mean()) if values.size else float("nan")
            entry[f"{figure}_sd"] = float(values.std()) if values.size else float("nan")
        out.append(entry)
    return out
