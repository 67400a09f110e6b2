"""Choosing the image model by K-fold cross-validation (:func:`select_model`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from brachycal.calibration.chain.fit import fit_chain, fit_problem
from brachycal.calibration.chain.image_models import MODELS, image_model
from brachycal.calibration.chain.layout import ParameterLayout
from brachycal.calibration.chain.problem import ChainProblem
from brachycal.calibration.chain.result import ChainFit
from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.sequential import CalibrationResult
from brachycal.data.session import Session
from brachycal.errors import DegenerateDataError
from brachycal.model.robot import Robot


def cross_validate(
    session: Session,
    robot: Robot,
    initial: CalibrationResult,
    model: str,
    folds: int = 8,
    seed: int = 0,
    exclude: np.ndarray | None = None,
    start: ChainFit | None = None,
) -> ErrorStats:
    """K-fold cross-validated image error of a chain model: each fold's samples predicted by a fit
    without them (a full refit: robust stage, flags, settled noise levels, solved to the last
    digit). Samples in ``exclude`` (flagged outliers) are fitted robustly but not scored.

    ``start``: a fit of this model on the same session from the same sequential result (e.g. the
    final fit, which each leave-one-out fold is close to), whose estimate and settled noise levels
    the first fold starts from (else the sequential result); each next fold starts from the
    previous fold's fit. The folds' estimates do not depend on where they start (each stage is
    solved to its tolerance, the noise levels settle to their fixed point), only their iterations
    do (:func:`~brachycal.calibration.chain.fit.fit_problem`).

    Raises:
        DegenerateDataError: a fold's training samples do not determine the chain.
    """
    n = len(session.uv_px)
    order = np.random.default_rng(seed).permutation(n)
    errors = np.empty(n)
    problem, x = ChainProblem.start(session, robot, initial, ParameterLayout(model))  # flange poses once
    settled = None
    if start is not None:
        x = start.x[: problem.layout.size]  # the fixed blocks and scales come first (then any joint offsets)
        settled = start.sigma_m
    for fold in range(folds):
        held = np.zeros(n, dtype=bool)
        held[order[fold::folds]] = True
        try:
            fit = fit_problem(problem, x, samples=~held, rounds=1, robot_accuracy=None, settle_from=settled)
        except DegenerateDataError as exc:
            left_out = ", ".join(session.sample_ids[i] for i in np.flatnonzero(held)[:3])
            raise DegenerateDataError(f"{model} cross-validation without sample(s) {left_out}: {exc.problem}") from None
        # The next fold starts here: its estimates differ from this fold's by a few samples' pull (its
        # robust stage from this one's, both with rounds=1; its noise levels from these settled ones).
        x = fit.robust_x if fit.robust_x is not None else fit.x
        settled = fit.sigma_m
        errors[held] = np.linalg.norm(fit.image_residuals[held], axis=1)
    keep = np.ones(n, dtype=bool) if exclude is None else ~np.asarray(exclude, dtype=bool)
    return ErrorStats(errors[keep])


@dataclass(frozen=True)
class ModelChoice:
    """The chosen image model and the evidence: cross-validated errors per model (outliers not scored).

    ``undetermined`` lists the models the data cannot determine (model → the reason), left out.
    """

    model: str
    cv: dict[str, ErrorStats]
    rule: str
    scored_samples: int
    undetermined: dict[str, str] = field(default_factory=dict)

    def evidence(self) -> dict[str, dict[str, float]]:
        """Per model: cross-validated RMSE and MAE (mm) and the RMSE's standard error (mm)."""
        out = {}
        for m, s in self.cv.items():
            squares = (s.errors_m * 1e3) ** 2
            se_rmse = float(np.std(squares) / np.sqrt(s.n) / (2 * s.rmse_mm))  # delta method on mean(e²)
            out[m] = {"cv_rmse_mm": s.rmse_mm, "cv_mae_mm": s.mae_mm, "se_mm": se_rmse}
        return out


def select_model(
    session: Session, robot: Robot, initial: CalibrationResult, models: tuple[str, ...] = MODELS, folds: int = 8
) -> ModelChoice:
    """Choose the image model by K-fold CV: the simplest model within one standard error of the best.

    Samples that the most flexible determined model flags as gross outliers are left out of the
    scores (they would dominate every model's error alike). A model the data cannot determine
    (:func:`check_conditioning`) is left out of the choice, with its reason.

    Raises:
        DegenerateDataError: no model is determined by the data.
    """
    undetermined: dict[str, str] = {}
    flagged = None
    for m in sorted(models, key=lambda m: -image_model(m).complexity):
        try:
            flagged = fit_chain(session, robot, initial, m, robot_accuracy=None).outliers
            break
        except DegenerateDataError as exc:
            undetermined[m] = exc.problem
    if flagged is None:
        raise DegenerateDataError(next(iter(undetermined.values())))
    cv = {}
    for m in models:
        if m in undetermined:
            continue
        try:
            cv[m] = cross_validate(session, robot, initial, m, folds, exclude=flagged)
        except DegenerateDataError as exc:
            undetermined[m] = exc.problem
    if not cv:
        raise DegenerateDataError(next(iter(undetermined.values())))
    rule = "simplest model within one standard error of the lowest cross-validated RMSE (outliers not scored)"
    evidence = ModelChoice("", cv, rule, int((~flagged).sum())).evidence()
    best = min(evidence, key=lambda m: evidence[m]["cv_rmse_mm"])
    limit = evidence[best]["cv_rmse_mm"] + evidence[best]["se_mm"]
    eligible = [m for m in cv if evidence[m]["cv_rmse_mm"] <= limit]
    chosen = min(eligible, key=lambda m: (image_model(m).complexity, evidence[m]["cv_rmse_mm"]))
    return ModelChoice(chosen, cv, rule, int((~flagged).sum()), undetermined)
