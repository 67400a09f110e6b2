"""The whole-chain method end to end: model selection, fit, leave-one-out, uncertainty, JSON.

``calibrate_chain`` is what ``brachycal calibrate --solve chain`` runs: the sequential result as
the start, the image model chosen by 8-fold cross-validation, the chain fitted with it (gross
outliers flagged and left out), its leave-one-out image error (comparable with Table II), 95 %
intervals from the covariance (and, if asked, from a bootstrap that resamples the images and the
touches), and the predicted landing error over the recorded sample poses (the prostate cube) and
over the image at the central pose.

Conditioning: the fit refuses data that do not determine the chain
(:func:`~brachycal.calibration.chain.check_conditioning`). In the grey zone — determined, but
the predicted landing RMS somewhere in the image above :data:`WARN_LANDING_RMS_MM` — it warns
(:class:`~brachycal.errors.ConditioningWarning`): the calibration's own predicted error there
exceeds what the paper's method achieves overall, so the samples do not support the chain's
accuracy over the image (they cover too small a part of it, or too few probe poses).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial
from statistics import NormalDist
from typing import TYPE_CHECKING, Any

import numpy as np

from brachycal._lazy import renamed
from brachycal.calibration.chain import (
    DEFAULT_ROBOT_ACCURACY,
    OUTLIER_THRESHOLD,
    RCOND_LIMIT,
    ROTATION_SD_LIMIT,
    SCANNER_SOUND_SPEED,
    ChainFit,
    ModelChoice,
    RobotAccuracy,
    fit_chain,
    image_model,
    select_model,
)
from brachycal.calibration.chain.model_choice import FoldRuns
from brachycal.calibration.chain.uncertainty import Bootstrap, bootstrap, landing_covariance, predicted_rms_mm
from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.parallel import parallel_calls
from brachycal.calibration.result import Calibration
from brachycal.calibration.robot.identification import (
    IDENTIFICATION_FOLDS,
    IdentificationResult,
    choose_and_identify,
    cross_validate_identification,
)
from brachycal.calibration.sequential.method import SequentialResult
from brachycal.data.session import Session
from brachycal.errors import ConditioningWarning, InputError
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray

#: Predicted landing RMS (mm) above which a chain calibration warns: the paper's leave-one-out
#: MAE of its rigid method (Table II, 0.65 mm). Sessions spanning the prostate cube predict
#: 0.27–0.31 mm at the image's far corners (twin seeds 0–19, `benchmarks/chain_checks.py`).
WARN_LANDING_RMS_MM = 0.65
#: Cost of one predicted landing error map, milliseconds of one core (~30 on the example session,
#: its 64 sample poses or its 216-pixel image map alike: mostly the robot's Jacobians' set-up;
#: :data:`~brachycal.calibration.chain.model_choice.FOLD_COST_MS`'s unit): it only decides which
#: process computes it beside the leave-one-out's folds, never a result.
LANDING_COST_MS = 30.0


@dataclass(frozen=True, repr=False)
class ChainResult:
    """Everything the chain method measured on a session.

    Attributes:
        choice: the chosen image model and the cross-validation evidence.
        fit: the chain fitted with the chosen model on all samples (outliers left out).
        loocv: leave-one-out image error of the chain (Table II's definition).
        predicted_cube_mm: ``(N,)`` predicted RMS landing error at each sample pose and pixel.
        fov_px: ``(G, 2)`` pixels of the image map; ``predicted_fov_mm`` ``(G,)`` its predicted RMS
            landing error (probe at the central sample pose).
        bootstrap: replicates, if requested.
        identification: the identified robot, if requested (then ``fit`` is on the corrected robot).
        identification_cv: image error at held-out configurations, ``(chain alone, with the
            robot identified)`` (K-fold, each fold identifies the robot again), if identified.
        joint_origins: ``{joint: {"urdf": (4, 4), "corrected": (4, 4)}}`` when the result corrects
            the robot (identification or joint offsets): what the result file stores so that a
            corrected URDF is recognised and never corrected twice.
    """

    choice: ModelChoice
    fit: ChainFit
    loocv: ErrorStats
    predicted_cube_mm: FloatArray
    fov_px: FloatArray
    predicted_fov_mm: FloatArray
    bootstrap: Bootstrap | None
    identification: IdentificationResult | None = None
    identification_cv: tuple[ErrorStats, ErrorStats] | None = None
    joint_origins: dict[str, dict[str, FloatArray]] | None = None

    def __repr__(self) -> str:
        identified = "" if self.identification is None else ", robot identified"
        return "\n".join(
            [
                f"ChainResult: the whole chain, image model {self.choice.model!r}{identified}; "
                f"leave-one-out RMSE {self.loocv.rmse_mm:.3f} mm over {self.loocv.n} samples",
                *("  " + line for line in repr(self.calibration()).splitlines()),
            ]
        )

    def calibration(self) -> Calibration:
        """The chain's :class:`~brachycal.calibration.result.Calibration`, with its robot corrections
        (joint offsets and the corrected joint origins, as the result file stores them)."""
        origins = {k: (v["urdf"], v["corrected"]) for k, v in (self.joint_origins or {}).items()}
        return replace(self.fit.calibration(), joint_origins=origins)

    def intervals(self, level: float = 0.95) -> dict[str, dict[str, object]]:
        """Intervals at ``level`` of the quantities a user asks about.

        From the covariance (normal theory: the session's noise and, with a stated robot accuracy,
        the robot model's own error; see :mod:`brachycal.calibration.chain`), and with a bootstrap
        its percentile intervals under ``bootstrap_<name>`` (the session's noise only: resampling
        the session cannot see the robot's error).
        """
        z = NormalDist().inv_cdf(0.5 + level / 2)  # the standard library's: scipy.stats costs 0.5 s to import
        sd = self.fit.parameter_sd()
        fit = self.fit
        out: dict[str, dict[str, object]] = {}
        for key, name in (("p_ER_Ntip_mm", "p_ER_Ntip"), ("p_EL_Ptip_mm", "p_EL_Ptip")):
            k = fit.block(name)
            out[key] = _bounds(fit.x[k] * 1e3, z * sd[k] * 1e3)
        k = fit.block("scale")
        image = image_model(fit.model)
        if image.n_scale:
            out["scale"] = _bounds(fit.x[k], z * sd[k])
        if image.scale_is_sound_speed:
            out["sound_speed_m_s"] = _bounds(fit.x[k] * SCANNER_SOUND_SPEED, z * sd[k] * SCANNER_SOUND_SPEED)
        if self.bootstrap is not None:
            for name, values in self.bootstrap.values.items():
                if np.all(np.isfinite(values)):
                    lo, hi = self.bootstrap.interval(name, level)
                    scale = 1e3 if name != "sound_speed_m_s" else 1.0
                    out[f"bootstrap_{name}"] = {
                        "low": np.atleast_1d(lo * scale).tolist(),
                        "high": np.atleast_1d(hi * scale).tolist(),
                    }
        return out


def _bounds(value: FloatArray, half: FloatArray) -> dict[str, object]:
    return {
        "value": np.atleast_1d(value).tolist(),
        "low": np.atleast_1d(value - half).tolist(),
        "high": np.atleast_1d(value + half).tolist(),
    }


def calibrate_chain(
    session: Session,
    robot: Robot,
    initial: SequentialResult,
    *,
    bootstrap_replicates: int = 0,
    joint_offsets: bool = False,
    robot_accuracy: RobotAccuracy | None = DEFAULT_ROBOT_ACCURACY,
    map_step_px: float = 60.0,
    progress: Callable[[int], None] | None = None,
    identify: bool = False,
    choice: ModelChoice | None = None,
    stage: Callable[[str], None] | None = None,
) -> ChainResult:
    """Run the whole-chain method on a session (see the module docstring).

    ``robot_accuracy``: the robot's stated kinematic accuracy, included in the intervals and the
    predicted landing error (:class:`~brachycal.calibration.chain.RobotAccuracy`; None: the
    session's noise alone). With ``identify``, the robot's geometry is identified jointly with the
    chain, that accuracy its prior (:mod:`brachycal.calibration.robot.identification`); the fit,
    leave-one-out and predicted landing error are then on the corrected robot, and the K-fold
    image error at held-out configurations is measured with and without identification.

    ``choice``: the image model already chosen on this session from ``initial``'s start
    (:class:`~brachycal.calibration.chain.ModelSelection`, e.g. while the sequential method's
    leave-one-out shared the cores); else :func:`~brachycal.calibration.chain.select_model` runs here.

    ``stage``: called with a line naming each stage as it starts, with its counts (for a progress
    display; the identification's held-out folds one line each).

    The leave-one-out's runs of folds and the two predicted landing errors are independent: they
    share the cores (:func:`~brachycal.calibration.parallel.parallel_calls`), each computed as alone.

    Raises:
        DegenerateDataError: the data do not determine the chain.
        InputError: ``identify`` with joint offsets (it replaces them) or without a robot accuracy.

    Warns:
        ConditioningWarning: the predicted landing RMS exceeds :data:`WARN_LANDING_RMS_MM` somewhere
            in the image (in its imaging sector when the session states one) or at a sample pose.
    """
    identification, identification_cv, joint_origins = None, None, None
    if identify:
        if joint_offsets:
            raise InputError("robot identification replaces the joint offsets: ask for one or the other")
        if robot_accuracy is None:
            raise InputError("robot identification needs the robot's stated accuracy (its prior)")

        n, folds = len(session.uv_px), IDENTIFICATION_FOLDS
        say = stage if stage is not None else lambda line: None
        say(f"robot identification: image model choice, then the robot with the chain over {n} samples")
        choice, identification = choose_and_identify(session, robot, initial, robot_accuracy)
        started = [1]

        def next_fold(count: int) -> None:
            started[0] += count
            if started[0] <= folds:
                say(f"held-out configurations: fold {started[0]} of {folds} (the chain, then the chain and robot)")

        say(f"held-out configurations: fold 1 of {folds} (the chain, then the chain and robot)")
        identification_cv = cross_validate_identification(
            session, robot, initial, choice.model, robot_accuracy, folds, progress=next_fold
        )
        fit, nominal, robot = identification.fit, robot, identification.robot(robot)
        joint_origins = _origins(nominal, robot)
    else:
        if choice is None:
            choice = select_model(session, robot, initial)
        fit = fit_chain(
            session, robot, initial, choice.model, joint_offsets=joint_offsets, robot_accuracy=robot_accuracy
        )
        if fit.joint_offsets_rad:
            joint_origins = _origins(robot, robot.with_joint_offsets(fit.joint_offsets_rad))
    width, height = session.size_px
    grid = np.array([(u, v) for v in np.arange(0, height, map_step_px) for u in np.arange(0, width, map_step_px)])
    centre = session.samples_q[np.argmin(np.linalg.norm(session.uv_px - session.uv_px.mean(axis=0), axis=1))]
    runs = FoldRuns.of(session, robot, initial, choice.model, folds=len(session.uv_px), start=fit)
    if stage is not None:
        stage(f"the chain's leave-one-out over {len(session.uv_px)} samples and its predicted landing error")
    landings = [(session.samples_q, session.uv_px), (np.repeat(centre[None], len(grid), 0), grid)]
    shared: list[Callable[[], Any]] = [
        *runs.calls(),
        *(partial(landing_covariance, fit, robot, session.spacing_m, q, uv) for q, uv in landings),
    ]
    outcomes = parallel_calls(shared, [*runs.costs(), *(LANDING_COST_MS for _ in landings)])
    loocv = ErrorStats(runs.errors(outcomes[: len(runs.runs)]))
    cube, fov = (predicted_rms_mm(C) for C in outcomes[len(runs.runs) :])
    # Over the imaging sector when the session states one: pixels outside it never show a needle.
    shown = fov if session.sector is None else fov[session.sector.margin_to_edge(grid, session.spacing_m) >= 0]
    worst = max(float(shown.max()) if shown.size else 0.0, float(cube.max()))
    if worst > WARN_LANDING_RMS_MM:
        span = np.ptp(session.uv_px[~fit.outliers], axis=0)
        warnings.warn(
            f"whole chain: predicted landing error up to {worst:.2f} mm RMS in the "
            f"{'image' if session.sector is None else 'imaging sector'} or at the sample poses (more than "
            f"{WARN_LANDING_RMS_MM} mm): the {int((~fit.outliers).sum())} samples span {span[0]:.0f} x "
            f"{span[1]:.0f} px of the {width} x {height} px image; spread them over the image and the probe poses",
            ConditioningWarning,
            stacklevel=2,
        )
    boot = None
    if bootstrap_replicates:
        boot = bootstrap(session, robot, fit, bootstrap_replicates, progress=progress)
    return ChainResult(choice, fit, loocv, cube, grid, fov, boot, identification, identification_cv, joint_origins)


def _origins(nominal: Robot, corrected: Robot) -> dict[str, dict[str, FloatArray]]:
    return {
        name: {"urdf": nominal.joint_origin(name), "corrected": corrected.joint_origin(name)}
        for name in nominal.joint_names
    }


def chain_json(report: ChainResult, sample_ids: list[str]) -> dict:
    """The ``chain`` section of a result file (every number finite)."""
    fit = report.fit
    conditioning = fit.conditioning
    return {
        "model": fit.model,
        "model_selection": {
            "rule": report.choice.rule,
            "folds": 8,
            "scored_samples": report.choice.scored_samples,
            "evidence": report.choice.evidence(),
            "undetermined": report.choice.undetermined,
        },
        "sound_speed_m_s": fit.sound_speed_m_s,
        "noise_sd_mm": {k: v * 1e3 for k, v in fit.sigma_m.items()},
        "noise": {g: {"sd_mm": n.sd_m * 1e3, "residual_dof": n.dof, "source": n.source} for g, n in fit.noise.items()},
        "image_noise_along_axes": {
            a: {"sd_mm": n.sd_m * 1e3, "residual_dof": n.dof} for a, n in fit.image_axes_noise.items()
        },
        "outliers": [s for s, flagged in zip(sample_ids, fit.outliers, strict=True) if flagged],
        "outlier_rule": f"3D image residual above {OUTLIER_THRESHOLD} x sqrt(3) x the image noise SD; "
        "flagged samples are left out of the final fit",
        "fitted_samples": int((~fit.outliers).sum()),
        "intervals_95": report.intervals(),
        "intervals_contain": "the session's noise and the stated robot accuracy (robot_accuracy; see the documentation)"
        if fit.robot_accuracy is not None
        else "the session's noise, not the robot model's own error (see the documentation)",
        "robot_accuracy": None if fit.robot_accuracy is None else fit.robot_accuracy.as_json(),
        "noise_share_after_robot": fit.noise_share,
        "conditioning": {
            "rcond": conditioning.rcond if conditioning else None,
            "rcond_limit": RCOND_LIMIT,
            "rotation_sd_deg": {k: float(np.degrees(v)) for k, v in conditioning.rotation_sd_rad.items()}
            if conditioning
            else {},
            "rotation_sd_limit_deg": float(np.degrees(ROTATION_SD_LIMIT)),
        },
        "predicted_landing_rms_mm": {
            "samples": {
                "mean": float(report.predicted_cube_mm.mean()),
                "max": float(report.predicted_cube_mm.max()),
                "per_sample": report.predicted_cube_mm.tolist(),
            },
            "image_map": {"pixels": report.fov_px.tolist(), "rms_mm": report.predicted_fov_mm.tolist()},
            "warn_above_mm": WARN_LANDING_RMS_MM,
        },
        "bootstrap_replicates": 0 if report.bootstrap is None else len(next(iter(report.bootstrap.values.values()))),
        "joint_offsets_rad": fit.joint_offsets_rad,
        **_robot_json(report),
    }


def _robot_json(report: ChainResult) -> dict[str, object]:
    out: dict[str, object] = {}
    if report.identification is not None:
        identified = report.identification.as_json()
        if report.identification_cv is not None:
            chain_alone, identified_cv = report.identification_cv
            identified["held_out_configurations"] = {
                "folds": IDENTIFICATION_FOLDS,
                "image_rmse_mm": {"chain": chain_alone.rmse_mm, "chain_and_robot": identified_cv.rmse_mm},
                "image_mae_mm": {"chain": chain_alone.mae_mm, "chain_and_robot": identified_cv.mae_mm},
            }
        out["robot_identification"] = identified
    if report.joint_origins is not None:
        out["robot_joint_origins"] = {
            name: {kind: T.tolist() for kind, T in pair.items()} for name, pair in report.joint_origins.items()
        }
    return out


#: Former names, given for one release with a DeprecationWarning.
if not TYPE_CHECKING:  # type checkers see only the new names
    __getattr__ = renamed(__name__, {"ChainReport": "ChainResult"})
