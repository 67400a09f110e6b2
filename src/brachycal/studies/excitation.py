"""Excitation poses on the twin: record the chosen extra touches and samples with the physical robot,
then judge identification with and without them against the twin's truth.

Recording (:func:`record_extra`), as the twin records its session (:mod:`brachycal.simulation.twin`):

- a **touch**: the operator jogs the physical tool tip onto the true reference tip (plus the twin's
  jog error) keeping the planned approach (the tool's orientation at the commanded joints); the
  joints are read with encoder noise.
- a **sample**: the needle arm goes to its commanded joints; the probe is adjusted until the needle
  tip shows at the planned pixel (the probe arm keeps its posture, out-of-plane offset within the
  beam); the joints are read, the pixel annotated with the twin's annotation noise.

The extra data draw from their own random stream (seeded by the twin's seed), so the session's
draws are unchanged.

Evaluation (:func:`evaluate_excitation`): the twin's session identified as ``calibrate --method
chain --identify-robot`` does (prior = the twin's own robot-error level), the excitation chosen on
it (:func:`brachycal.planning.excitation.plan_excitation`), recorded (whether or not it was judged
worth recording: the point is to compare the prediction with the outcome), and the robot identified again
on the session plus the extra data; targeting (30 targets) and held-out targeting (torso turned 3°)
with each, and the criterion's predicted RMS landing error before and after. Two controls with as
many extra observations: plain repeats of the chosen poses' source poses (do the new configurations
matter, or only where and how much is sampled?) and repeats of session samples drawn at random
(does the criterion's choice matter, or only the count?).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from brachycal.calibration import calibrate
from brachycal.calibration.chain import RobotAccuracy
from brachycal.calibration.robot.identification import IdentificationResult, choose_and_identify, identify_robot
from brachycal.calibration.robot.observability import SAMPLE, Observation, extended_session
from brachycal.data.session import Session
from brachycal.imaging.pixels import image_points
from brachycal.model.ik import solve_ik
from brachycal.model.names import NEEDLE_TIP, PROBE_TIP, TOP_MODEL_TIP, US_IMAGE
from brachycal.model.robot import Robot
from brachycal.planning.excitation import plan_excitation
from brachycal.planning.robot_time import DEFAULT_BUDGET_MINUTES
from brachycal.se3 import make_transform
from brachycal.simulation.settings import HELD_OUT_TORSO_TURN_RAD
from brachycal.simulation.twin import Twin, TwinConfig, simulate
from brachycal.studies.targeting import targeting_error

_FRAMES = {"needle": NEEDLE_TIP, "probe": PROBE_TIP, "top_model": TOP_MODEL_TIP}


def _stream(seed: int) -> np.random.Generator:
    # Separate from the twin's STREAMS: "excitation" spawned from the same seed under another key.
    return np.random.default_rng(np.random.SeedSequence([seed, 19]))


def record_extra(twin: Twin, planned: Sequence[Observation]) -> list[Observation]:
    """The planned observations as the twin's lab would record them (module docstring): read joints
    ``q (nq,)`` and annotated pixels.

    Raises:
        SolverError: the physical robot cannot make one of them.
    """
    config, truth, physical = twin.config, twin.truth, twin.physical
    rig = twin.nominal.rig
    rng = _stream(config.seed)
    rtips = {"rtip1": truth.p_R_Rtip1, "rtip2": truth.p_R_Rtip2}
    out = []
    for obs in planned:
        q = np.asarray(obs.q, dtype=float)
        if obs.kind == SAMPLE:
            e = rng.uniform(-0.5, 0.5) * config.beam_thickness_m if config.out_of_plane else 0.0
            tip = physical.fk(NEEDLE_TIP, q)[:3, 3]
            R_image = physical.fk(US_IMAGE, q)[:3, :3]
            origin = tip - R_image @ image_points(obs.uv_px, truth.spacing_m, e)[0]
            q_true = solve_ik(
                physical, US_IMAGE, make_transform(R_image, origin), q, rig.probe_arm_indices, margin=0.0, restarts=0
            )
            uv = np.asarray(obs.uv_px, dtype=float).copy()
            if config.annotation_noise:
                uv = uv + rng.normal(scale=config.annotation_sd_px, size=2)
        else:
            frame = _FRAMES[obs.tool]
            arm = rig.probe_arm_indices if obs.tool == "probe" else rig.needle_arm_indices
            jog = rng.normal(scale=config.jog_sd_m, size=3) if config.jog_error else np.zeros(3)
            R = physical.fk(frame, q)[:3, :3]
            q_true = solve_ik(
                physical, frame, make_transform(R, rtips[obs.reference] + jog), q, arm, margin=0.0, restarts=0
            )
            uv = obs.uv_px
        read = q_true + rng.normal(scale=config.encoder_sd_rad, size=q_true.shape) if config.encoder_noise else q_true
        out.append(replace(obs, q=read, uv_px=uv))
    return out


def extended_twin_session(twin: Twin, planned: Sequence[Observation]) -> Session:
    """The twin's session with the planned observations recorded and appended."""
    return extended_session(twin.session, record_extra(twin, planned))


def evaluate_excitation(
    robot: Robot, seed: int, level: str, budget_minutes: float = DEFAULT_BUDGET_MINUTES, targets: int = 30
) -> dict[str, object]:
    """One twin session with robot error ``level``: identification with and without the excitation
    poses chosen for it (module docstring). One row: predicted and actual figures, minutes, counts."""
    config = TwinConfig(seed=seed).with_robot_error(level)
    twin = simulate(robot, config)
    accuracy = RobotAccuracy(config.link_offset_sd_m, config.link_tilt_sd_rad, config.encoder_sd_rad)
    initial = calibrate(twin.session, robot, ("scaled_uv",))
    choice, identified = choose_and_identify(twin.session, robot, initial, accuracy)
    plan = plan_excitation(identified, twin.session, robot, budget_minutes)
    extended = extended_twin_session(twin, plan.observations)
    again = identify_robot(extended, robot, initial, choice.model, accuracy) if plan.chosen else identified

    def targeting(ident: IdentificationResult) -> tuple[float, float]:
        fit, software = ident.fit, ident.robot(robot)
        hit = targeting_error(twin, fit.calibration(), targets, software=software)
        held = targeting_error(
            twin,
            fit.calibration(),
            targets,
            software=software,
            torso_turn_rad=HELD_OUT_TORSO_TURN_RAD,
        )
        return hit.stats.mae_mm, held.stats.mae_mm

    before, after = targeting(identified), targeting(again)
    # Control: as many observations, each a plain repeat of its source pose (same configuration):
    # does the variety of configurations matter, or only the number of observations?
    repeats = [replace(c.observation, q=c.source_q) for c in plan.chosen]
    control = (
        targeting(identify_robot(extended_twin_session(twin, repeats), robot, initial, choice.model, accuracy))
        if plan.chosen
        else before
    )
    # Second control: as many repeats of session samples drawn at random (not chosen by the criterion).
    n = len(twin.session.uv_px)
    drawn = np.random.default_rng(np.random.SeedSequence([seed, 19, 1])).choice(
        n, size=len(plan.chosen), replace=len(plan.chosen) > n
    )
    random_repeats = [Observation(SAMPLE, twin.session.samples_q[i], uv_px=twin.session.uv_px[i]) for i in drawn]
    random_control = (
        targeting(identify_robot(extended_twin_session(twin, random_repeats), robot, initial, choice.model, accuracy))
        if plan.chosen
        else before
    )
    kinds = [c.observation.kind for c in plan.chosen]
    return {
        "level": level,
        "seed": seed,
        "model": choice.model,
        "candidates": plan.candidates,
        "touches": kinds.count("touch"),
        "samples": kinds.count("sample"),
        "minutes": plan.minutes,
        "worth_it": plan.worth_it,
        "resolution": plan.resolution,
        "predicted_rms_before_mm": plan.rms_before_mm,
        "predicted_rms_after_mm": plan.rms_after_mm,
        "target_mae_before_mm": before[0],
        "target_mae_after_mm": after[0],
        "held_out_mae_before_mm": before[1],
        "held_out_mae_after_mm": after[1],
        "target_mae_repeats_mm": control[0],
        "held_out_mae_repeats_mm": control[1],
        "target_mae_random_repeats_mm": random_control[0],
        "held_out_mae_random_repeats_mm": random_control[1],
    }
