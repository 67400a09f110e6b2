"""Choosing the image model by K-fold cross-validation (:func:`select_model`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from brachycal.calibration.chain.fit import fit_chain, fit_problem
from brachycal.calibration.chain.image_models import MODELS, image_model
from brachycal.calibration.chain.layout import ParameterLayout
from brachycal.calibration.chain.problem import ChainProblem
from brachycal.calibration.chain.result import ChainFit
from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.parallel import parallel_calls
from brachycal.calibration.sequential.method import SequentialResult
from brachycal.data.session import Session
from brachycal.errors import DegenerateDataError
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray

#: Most folds in one run of warm starts (each fold starting from the previous one's fit). Longer
#: cross-validations (leave-one-out: one fold per sample) are cut into runs of at most this many
#: folds, each starting from the same fit, which different cores then share (:func:`parallel_calls`):
#: a fold starts a few samples' pull away from its start either way, so a run's length changes only
#: where the folds start, not what they converge to. The runs depend on the number of folds alone,
#: never on the cores, so the figures are the same on any machine.
FOLDS_PER_RUN = 32


def cross_validate(
    session: Session,
    robot: Robot,
    initial: SequentialResult,
    model: str,
    folds: int = 8,
    seed: int = 0,
    exclude: np.ndarray | None = None,
    start: ChainFit | None = None,
    *,
    folds_per_run: int | None = FOLDS_PER_RUN,
    workers: int | None = None,
) -> ErrorStats:
    """K-fold cross-validated image error of a chain model: each fold's samples predicted by a fit
    without them (a full refit: robust stage, flags, settled noise levels, solved to the last
    digit). Samples in ``exclude`` (flagged outliers) are fitted robustly but not scored.

    ``start``: a fit of this model on the same session from the same sequential result (e.g. the
    final fit, which each leave-one-out fold is close to), whose estimate and settled noise levels
    the first fold of each run starts from (else the sequential result); each next fold of a run
    starts from the previous fold's fit. The folds' estimates do not depend on where they start
    (each stage is solved to its tolerance, the noise levels settle to their fixed point), only
    their iterations do (:func:`~brachycal.calibration.chain.fit.fit_problem`), and where the noise
    levels' fixed-point iteration stops (relative change below 1e-6): a fold's error moves by up to
    ~3e-8 mm with its start, the figures over all folds by ~1e-9 mm (``tests/test_chain_parallel.py``).

    ``folds_per_run``: at most this many folds per run of warm starts (:data:`FOLDS_PER_RUN`;
    None: one run); the runs share ``workers`` processes (default: the cores, :func:`parallel_calls`).

    Raises:
        DegenerateDataError: a fold's training samples do not determine the chain.
    """
    errors = fold_errors(session, robot, initial, model, folds, seed, start, folds_per_run, workers)
    keep = np.ones(len(errors), dtype=bool) if exclude is None else ~np.asarray(exclude, dtype=bool)
    return ErrorStats(errors[keep])


def fold_errors(
    session: Session,
    robot: Robot,
    initial: SequentialResult,
    model: str,
    folds: int = 8,
    seed: int = 0,
    start: ChainFit | None = None,
    folds_per_run: int | None = FOLDS_PER_RUN,
    workers: int | None = None,
) -> FloatArray:
    """``(N,)`` each sample's cross-validated image error (metres) of :func:`cross_validate`, outliers
    included."""
    runs = FoldRuns.of(session, robot, initial, model, folds, seed, start, folds_per_run)
    return runs.errors(parallel_calls(runs.calls(), runs.costs(), workers))


#: Cost of one fold's refit, milliseconds of one core on the 64-sample example session (8-fold
#: cross-validation from the sequential start ~11, a leave-one-out fold from the final fit ~9):
#: it only decides which process runs which run of folds (:func:`parallel_calls`), never a result.
FOLD_COST_MS = 10.0


@dataclass(frozen=True)
class FoldRuns:
    """The folds of one cross-validation cut into runs of warm starts (:func:`cross_validate`): one
    call per run, which other work may share the cores with (:func:`parallel_calls`), then
    :meth:`errors` of their outcomes."""

    session: Session
    model: str
    folds: int
    order: np.ndarray
    problem: ChainProblem
    x: FloatArray
    settled: dict[str, float] | None
    runs: tuple[range, ...]

    @classmethod
    def of(
        cls,
        session: Session,
        robot: Robot,
        initial: SequentialResult,
        model: str,
        folds: int = 8,
        seed: int = 0,
        start: ChainFit | None = None,
        folds_per_run: int | None = FOLDS_PER_RUN,
    ) -> FoldRuns:
        """The runs of :func:`cross_validate` (same arguments)."""
        n = len(session.uv_px)
        order = np.random.default_rng(seed).permutation(n)
        problem, x = ChainProblem.start(session, robot, initial, ParameterLayout(model))  # flange poses once
        settled = None
        if start is not None:
            x = start.x[: problem.layout.size]  # the fixed blocks and scales come first (then any joint offsets)
            settled = start.sigma_m
        size = folds if folds_per_run is None else max(1, folds_per_run)
        runs = tuple(range(first, min(first + size, folds)) for first in range(0, folds, size))
        return cls(session, model, folds, order, problem, x, settled, runs)

    def calls(self) -> list[Callable[[], list[tuple[np.ndarray, FloatArray]]]]:
        """One call per run: ``[(held (N,) bool, errors of the held samples (metres)), ...]`` per fold."""
        return [partial(self.run, r) for r in self.runs]

    def costs(self) -> list[float]:
        """Each run's cost, milliseconds (:data:`FOLD_COST_MS` per fold)."""
        return [FOLD_COST_MS * len(r) for r in self.runs]

    def run(self, fold_range: range) -> list[tuple[np.ndarray, FloatArray]]:
        """The folds of one run, each starting from the previous one's fit."""
        session, problem, n, folds = self.session, self.problem, len(self.session.uv_px), self.folds
        x_fold, settled_fold = self.x, self.settled
        out = []
        for fold in fold_range:
            held = np.zeros(n, dtype=bool)
            held[self.order[fold::folds]] = True
            try:
                fit = fit_problem(
                    problem, x_fold, samples=~held, rounds=1, robot_accuracy=None, settle_from=settled_fold
                )
            except DegenerateDataError as exc:
                left_out = ", ".join(session.sample_ids[i] for i in np.flatnonzero(held)[:3])
                raise DegenerateDataError(
                    f"{self.model} cross-validation without sample(s) {left_out}: {exc.problem}"
                ) from None
            # The next fold starts here: its estimates differ from this fold's by a few samples' pull (its
            # robust stage from this one's, both with rounds=1; its noise levels from these settled ones).
            x_fold = fit.robust_x if fit.robust_x is not None else fit.x
            settled_fold = fit.sigma_m
            out.append((held, np.linalg.norm(fit.image_residuals[held], axis=1)))
        return out

    def errors(self, outcomes: list[list[tuple[np.ndarray, FloatArray]]]) -> FloatArray:
        """``(N,)`` each sample's error (metres) from the runs' outcomes (:meth:`calls`' order)."""
        errors = np.empty(len(self.session.uv_px))
        for part in outcomes:
            for held, e in part:
                errors[held] = e
        return errors


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


#: Cost of the most flexible model's fit that flags the outliers, milliseconds as :data:`FOLD_COST_MS`.
FLAGS_COST_MS = 20.0

#: One model-choice call's outcome: ``("ok", outliers or errors)``, ``("undetermined", reason)`` or
#: ``("error", exception)``.
ChoiceOutcome = tuple[str, object]


@dataclass(frozen=True)
class ModelSelection:
    """:func:`select_model` cut into its independent refits: the most flexible model's fit (the
    outlier flags) and every model's K-fold cross-validation, one call each (:meth:`calls`), which
    other work may share the cores with (:func:`parallel_calls`); then :meth:`choose`."""

    session: Session
    robot: Robot
    initial: SequentialResult
    models: tuple[str, ...]
    folds: int = 8

    @property
    def by_complexity(self) -> list[str]:
        return sorted(self.models, key=lambda m: -image_model(m).complexity)

    def job(self, item: tuple[str, str]) -> ChoiceOutcome:
        """``("ok", outliers or errors)``, ``("undetermined", reason)`` or ``("error", exception)`` of one
        fit or one model's CV."""
        kind, m = item
        try:
            if kind == "flags":
                return "ok", fit_chain(self.session, self.robot, self.initial, m, robot_accuracy=None).outliers
            return "ok", cross_validate(self.session, self.robot, self.initial, m, self.folds).errors_m  # all scored
        except DegenerateDataError as exc:
            return "undetermined", exc.problem
        except Exception as exc:  # raised by choose() if this model's CV is used (run alone, it would not be otherwise)
            return "error", exc

    def calls(self) -> tuple[list[Callable[[], ChoiceOutcome]], list[float]]:
        """The flags fit, then each model's CV (:attr:`models`' order), with their costs (milliseconds)."""
        items = [("flags", self.by_complexity[0]), *(("cv", m) for m in self.models)]
        costs = [FLAGS_COST_MS, *(FOLD_COST_MS * self.folds for _ in self.models)]
        return [partial(self.job, item) for item in items], costs

    def choose(self, outcomes: list[ChoiceOutcome]) -> ModelChoice:
        """The choice from :meth:`calls`' outcomes (:func:`select_model`'s rule).

        Raises:
            DegenerateDataError: no model is determined by the data.
        """
        by_complexity = self.by_complexity
        undetermined: dict[str, str] = {}
        flagged = None
        for m in by_complexity:  # the most flexible determined model flags the outliers
            kind, value = self.job(("flags", m)) if m != by_complexity[0] else outcomes[0]
            if kind == "error":
                assert isinstance(value, Exception)
                raise value
            if kind == "ok":
                flagged = np.asarray(value, dtype=bool)
                break
            undetermined[m] = str(value)
        if flagged is None:
            raise DegenerateDataError(next(iter(undetermined.values())))
        cv = {}
        for m, (kind, value) in zip(self.models, outcomes[1:], strict=True):
            if m in undetermined:
                continue
            if kind == "error":
                assert isinstance(value, Exception)
                raise value
            if kind == "ok":
                cv[m] = ErrorStats(np.asarray(value)[~flagged])
            else:
                undetermined[m] = str(value)
        if not cv:
            raise DegenerateDataError(next(iter(undetermined.values())))
        rule = "simplest model within one standard error of the lowest cross-validated RMSE (outliers not scored)"
        evidence = ModelChoice("", cv, rule, int((~flagged).sum())).evidence()
        best = min(evidence, key=lambda m: evidence[m]["cv_rmse_mm"])
        limit = evidence[best]["cv_rmse_mm"] + evidence[best]["se_mm"]
        eligible = [m for m in cv if evidence[m]["cv_rmse_mm"] <= limit]
        chosen = min(eligible, key=lambda m: (image_model(m).complexity, evidence[m]["cv_rmse_mm"]))
        return ModelChoice(chosen, cv, rule, int((~flagged).sum()), undetermined)


def select_model(
    session: Session,
    robot: Robot,
    initial: SequentialResult,
    models: tuple[str, ...] = MODELS,
    folds: int = 8,
    *,
    workers: int | None = None,
) -> ModelChoice:
    """Choose the image model by K-fold CV: the simplest model within one standard error of the best.

    Samples that the most flexible determined model flags as gross outliers are left out of the
    scores (they would dominate every model's error alike). A model the data cannot determine
    (:func:`check_conditioning`) is left out of the choice, with its reason.

    The most flexible model's fit and every model's cross-validation are independent refits: they
    share ``workers`` processes (default: the cores, :func:`parallel_calls`); each is the same as run
    alone (:class:`ModelSelection`).

    Raises:
        DegenerateDataError: no model is determined by the data.
    """
    selection = ModelSelection(session, robot, initial, tuple(models), folds)
    return selection.choose(parallel_calls(*selection.calls(), workers))
