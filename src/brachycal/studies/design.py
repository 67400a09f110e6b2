"""Design of experiments: which sample poses buy the most targeting accuracy per minute of robot time.

Designs compared (all in the same 40 mm cube, aligned with the image as the planner does): the
paper's 4 × 4 × 4 grid, a 3 × 3 × 3 grid, uniformly random points (27 and 64), and an
**optimal** 27-point design chosen greedily from a 5 × 5 × 5 candidate grid to minimise the
predicted mean squared landing error over the cube (an A-optimal criterion on the whole-chain
information: ``mean_t trace(G_t I⁻¹ G_tᵀ)``, with ``I`` the touches' and axes' information plus the
chosen samples' ``J_iᵀ J_i``).

Each design is planned, simulated on the twin and calibrated with the whole-chain method (the
speed-of-sound image model, so designs are compared like for like); its predicted RMS landing
error over the cube comes from the fit's covariance, its actual error from the twin's truth.
Robot time: 5 min for the mechanical part (the paper's figure), 10 s per image sample (the
paper's: move, image, annotate), and the planned motion at a quarter of the vendor's speed.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np

from brachycal.calibration import calibrate
from brachycal.calibration.chain import fit_chain, information_blocks
from brachycal.calibration.chain.uncertainty import landing_covariance, landing_jacobian, predicted_rms_mm
from brachycal.errors import InputError
from brachycal.model.robot import Robot
from brachycal.planning import plan_poses
from brachycal.planning.robot_time import (
    DEFAULT_BUDGET_MINUTES,
    MAX_BUDGET_MINUTES,
    MECHANICAL_MINUTES,
    SECONDS_PER_SAMPLE,
    SPEED_SCALE,
)
from brachycal.simulation.settings import DESIGNS, ROBOT_ERROR_LEVELS
from brachycal.simulation.twin import TwinConfig, simulate, spec_for
from brachycal.studies.excitation import evaluate_excitation
from brachycal.studies.targeting import targeting_error
from brachycal.validate import MAX_SEEDS, check_int, check_range


def grid_offsets(points: int, edge_m: float) -> np.ndarray:
    steps = (np.arange(points) - (points - 1) / 2) * edge_m / (points - 1)
    return np.array(
        [(steps[i], steps[j], steps[k]) for k in range(points) for j in range(points) for i in range(points)]
    )


def optimal_offsets(robot: Robot, k: int = 27, seed: int = 0, edge_m: float = 0.040) -> np.ndarray:
    """Greedy A-optimal ``k`` points from the 5 × 5 × 5 candidate grid (see the module docstring)."""
    candidates = grid_offsets(5, edge_m)
    twin = simulate(robot, TwinConfig(seed=seed, spec=replace(spec_for(robot, TwinConfig()), offsets_m=candidates)))
    session = twin.session
    result = calibrate(session, robot, ("scaled_uv",))
    fit = fit_chain(session, robot, result, "sound_speed")
    fixed, blocks = information_blocks(session, robot, fit)
    P = fixed.shape[0]
    G = landing_jacobian(fit, robot, session.spacing_m, session.samples_q, session.uv_px)[:, :, :P]
    H = np.einsum("tip,tiq->pq", G, G) / len(G)
    info = fixed + 1e-9 * np.eye(P)
    chosen: list[int] = []
    for _ in range(k):
        best, best_score = -1, np.inf
        for i in range(len(blocks)):
            if i in chosen:
                continue
            trial = info + blocks[i].T @ blocks[i]
            score = np.trace(np.linalg.solve(trial, H))
            if score < best_score:
                best, best_score = i, score
        chosen.append(best)
        info = info + blocks[best].T @ blocks[best]
    # the candidate session's samples are in visiting order; map back to candidate offsets
    names = session.sample_ids
    return candidates[[int(names[i][1:]) - 1 for i in chosen]]


def design_offsets(name: str, robot: Robot, seed: int, edge_m: float = 0.040) -> np.ndarray:
    rng = np.random.default_rng(seed + 1000)
    if name == "grid 4x4x4":
        return grid_offsets(4, edge_m)
    if name == "grid 3x3x3":
        return grid_offsets(3, edge_m)
    if name.startswith("random"):
        return rng.uniform(-edge_m / 2, edge_m / 2, size=(int(name.split()[1]), 3))
    if name == "optimal 27":
        return optimal_offsets(robot, 27, seed, edge_m)
    raise ValueError(name)


def evaluate_design(robot: Robot, name: str, seed: int, targets: int = 30) -> dict[str, object]:
    """Plan, simulate and calibrate one design; predicted and actual landing error, robot minutes."""
    offsets = design_offsets(name, robot, seed)
    spec = replace(spec_for(robot, TwinConfig()), offsets_m=offsets)  # the robot's own workspace
    plan = plan_poses(robot, spec, speed_scale=SPEED_SCALE)
    twin = simulate(robot, TwinConfig(seed=seed, spec=spec))
    result = calibrate(twin.session, robot, ("scaled_uv",))
    fit = fit_chain(twin.session, robot, result, "sound_speed")
    reference = simulate(robot, TwinConfig(seed=seed)).session  # the 4x4x4 poses: the cube's targets
    predicted = predicted_rms_mm(
        landing_covariance(fit, robot, twin.session.spacing_m, reference.samples_q, reference.uv_px)
    )
    actual = targeting_error(twin, fit.calibration(), targets).stats
    minutes = MECHANICAL_MINUTES + (len(offsets) * SECONDS_PER_SAMPLE + plan.motion_time_s["optimised"]) / 60
    rms = float(np.sqrt(np.mean(predicted**2)))
    return {
        "design": name,
        "seed": seed,
        "samples": len(offsets),
        "robot_minutes": minutes,
        "predicted_rms_mm": rms,
        "actual_rms_mm": actual.rmse_mm,
        "actual_mae_mm": actual.mae_mm,
        "information_per_minute": 1.0 / (rms**2 * minutes),
    }


def compare_designs(
    robot: Robot,
    designs: Sequence[str] = DESIGNS,
    seeds: int = 3,
    *,
    progress: Callable[[int], None] | None = None,
) -> list[dict[str, object]]:
    """:func:`evaluate_design` for every design and seed ``0 .. seeds-1``: one row each, designs outermost.

    Args:
        robot: the nominal model.
        designs: names among :data:`DESIGNS`, each once.
        seeds: simulated sessions per design, in [1, 1000].
        progress: called with 1 as each row is done.

    Raises:
        InputError: an unknown or repeated design, or a seed count out of range.
    """
    check_int(seeds, "seeds", low=1, high=MAX_SEEDS)
    unknown = [d for d in designs if d not in DESIGNS]
    if unknown or len(set(designs)) != len(designs) or not designs:
        raise InputError(f"designs must be distinct names among {', '.join(DESIGNS)}, got {list(designs)!r}")
    rows = []
    for design in designs:
        for seed in range(seeds):
            rows.append(evaluate_design(robot, design, seed))
            if progress is not None:
                progress(1)
    return rows


def compare_excitation(
    robot: Robot,
    level: str,
    seeds: int = 3,
    budget_minutes: float = DEFAULT_BUDGET_MINUTES,
    *,
    progress: Callable[[int], None] | None = None,
) -> list[dict[str, object]]:
    """The 4 × 4 × 4 design plus excitation poses on twins whose robot is off its URDF by ``level``
    (:data:`~brachycal.simulation.settings.ROBOT_ERROR_LEVELS`), seeds ``0 .. seeds-1``: one row per
    seed (:func:`~brachycal.studies.excitation.evaluate_excitation`): the predicted RMS landing
    error and the targeting and held-out targeting MAE with the robot identified on the session alone,
    on the session plus the excitation poses, on the session plus as many plain repeats of their
    source poses and of session samples drawn at random; the extra robot minutes (on top of this
    design's :data:`MECHANICAL_MINUTES` and samples).

    Raises:
        InputError: an unknown level, a seed count or budget out of range, a robot without a
            shared joint.
    """
    check_int(seeds, "seeds", low=1, high=MAX_SEEDS)
    check_range(budget_minutes, "excitation budget", low=0.0, high=MAX_BUDGET_MINUTES, low_open=True, unit="min")
    if level not in ROBOT_ERROR_LEVELS:
        raise InputError(f"unknown robot-error level {level!r}; choose from {', '.join(ROBOT_ERROR_LEVELS)}")
    if not robot.rig.shared_indices:  # before minutes of work: the held-out postures turn the torso
        raise InputError(
            f"robot {robot.rig.name!r} has no joint shared by both arms: the excitation poses are judged at "
            "held-out postures made by turning it"
        )
    rows = []
    for seed in range(seeds):
        rows.append({"design": "grid 4x4x4 + excitation", **evaluate_excitation(robot, seed, level, budget_minutes)})
        if progress is not None:
            progress(1)
    return rows
