"""The whole-chain method end to end: model selection, fit, leave-one-out, uncertainty, JSON.

``calibrate_chain`` is what ``brachycal calibrate --method chain`` runs: the sequential result as
the start, the image model chosen by 8-fold cross-validation, the chain fitted with it, its
leave-one-out image error (comparable with Table II), 95 % intervals from the covariance (and,
if asked, from a bootstrap), and the predicted landing error over the recorded sample poses
(the prostate cube) and over the image at the central pose.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.stats import norm

from brachycal.calibration.chain import ChainFit, ModelChoice, cross_validate, fit_chain, select_model
from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.sequential import CalibrationResult
from brachycal.calibration.uncertainty import Bootstrap, bootstrap, landing_covariance, predicted_rms_mm
from brachycal.data.session import Session
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray


@dataclass(frozen=True)
class ChainReport:
    """Everything the chain method measured on a session.

    Attributes:
        choice: the chosen image model and the cross-validation evidence.
        fit: the chain fitted with the chosen model on all samples.
        loocv: leave-one-out image error of the chain (Table II's definition).
        predicted_cube_mm: ``(N,)`` predicted RMS landing error at each sample pose and pixel.
        fov_px: ``(G, 2)`` pixels of the image map; ``predicted_fov_mm`` ``(G,)`` its predicted RMS
            landing error (probe at the central sample pose).
        bootstrap: replicates, if requested.
    """

    choice: ModelChoice
    fit: ChainFit
    loocv: ErrorStats
    predicted_cube_mm: FloatArray
    fov_px: FloatArray
    predicted_fov_mm: FloatArray
    bootstrap: Bootstrap | None

    def intervals(self, level: float = 0.95) -> dict[str, dict[str, object]]:
        """95 % intervals of the quantities a user asks about (normal theory from the covariance)."""
        z = norm.ppf(0.5 + level / 2)
        sd = self.fit.parameter_sd()
        out: dict[str, dict[str, object]] = {
            "p_ER_Ntip_mm": _bounds(self.fit.x[0:3] * 1e3, z * sd[0:3] * 1e3),
            "p_EL_Ptip_mm": _bounds(self.fit.x[9:12] * 1e3, z * sd[9:12] * 1e3),
        }
        model = self.fit.model
        if model in ("similarity", "sound_speed", "scaled_uv"):
            k = slice(24, 24 + (2 if model == "scaled_uv" else 1))
            out["scale"] = _bounds(self.fit.x[k], z * sd[k])
        if model == "sound_speed":
            out["sound_speed_m_s"] = _bounds(self.fit.x[24:25] * 1540.0, z * sd[24:25] * 1540.0)
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
    initial: CalibrationResult,
    *,
    bootstrap_replicates: int = 0,
    joint_offsets: bool = False,
    map_step_px: float = 60.0,
    progress: Callable[[int], None] | None = None,
) -> ChainReport:
    """Run the whole-chain method on a session (see the module docstring)."""
    choice = select_model(session, robot, initial)
    fit = fit_chain(session, robot, initial, choice.model, joint_offsets=joint_offsets)
    loocv = cross_validate(session, robot, initial, choice.model, folds=len(session.uv_px))
    cube = predicted_rms_mm(landing_covariance(fit, robot, session.spacing_m, session.samples_q, session.uv_px))
    width, height = session.size_px
    grid = np.array([(u, v) for v in np.arange(0, height, map_step_px) for u in np.arange(0, width, map_step_px)])
    centre = session.samples_q[np.argmin(np.linalg.norm(session.uv_px - session.uv_px.mean(axis=0), axis=1))]
    fov = predicted_rms_mm(
        landing_covariance(fit, robot, session.spacing_m, np.repeat(centre[None], len(grid), 0), grid)
    )
    boot = None
    if bootstrap_replicates:
        boot = bootstrap(session, robot, initial, choice.model, bootstrap_replicates, progress=progress)
    return ChainReport(choice, fit, loocv, cube, grid, fov, boot)


def chain_json(report: ChainReport, sample_ids: list[str]) -> dict:
    """The ``chain`` section of a result file."""
    fit = report.fit
    return {
        "model": fit.model,
        "model_selection": {
            "rule": report.choice.rule,
            "folds": 8,
            "scored_samples": report.choice.scored_samples,
            "evidence": report.choice.evidence(),
        },
        "sound_speed_m_s": fit.sound_speed_m_s,
        "noise_sd_mm": {k: v * 1e3 for k, v in fit.sigma_m.items()},
        "outliers": [s for s, flagged in zip(sample_ids, fit.outliers, strict=True) if flagged],
        "intervals_95": report.intervals(),
        "predicted_landing_rms_mm": {
            "samples": {
                "mean": float(report.predicted_cube_mm.mean()),
                "max": float(report.predicted_cube_mm.max()),
                "per_sample": report.predicted_cube_mm.tolist(),
            },
            "image_map": {"pixels": report.fov_px.tolist(), "rms_mm": report.predicted_fov_mm.tolist()},
        },
        "bootstrap_replicates": 0 if report.bootstrap is None else len(next(iter(report.bootstrap.values.values()))),
        "joint_offsets_rad": fit.joint_offsets_rad,
    }
