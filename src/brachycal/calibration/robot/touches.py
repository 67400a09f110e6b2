"""Robot identification from touches of fixed points (MUKCa's protocol, the seed paper's reference tips).

A tool whose tip is a point fixed to the flange (a ball seated in a socket, a sharp tip in a
divot) touches ``K`` fixed points from many arm postures. Perfect kinematics would put the tip at
one position per point. Unknowns: the joint-origin corrections (:mod:`~brachycal.calibration.robot.arm_fit`),
the tip on the flange (3, metres in the flange frame) and each point (3, base frame); optionally
known distances between points (a machined block's sockets) as residuals of their own, with the
stated tolerance as their noise level. Each *place* (a recording with the points somewhere in the
workspace) has points of its own; the tip is shared.

The figure of merit is MUKCa's: per point, the mean distance of the tip (forward kinematics of
each touch) from the mean tip of that point, averaged over the points (:func:`touch_scatter`),
and the error of the known distances. A calibration is judged on places it did not use.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from brachycal.calibration.robot.arm_fit import (
    ArmFit,
    Evaluation,
    ParameterSelection,
    check_dynamics,
    deflection_columns,
    fit_arm,
    flange_points,
    gravity_moments,
    prior_sd,
)
from brachycal.calibration.robot.defaults import TOUCHES_ACCURACY as TOUCHES_ACCURACY  # the protocol's default
from brachycal.calibration.robot.evidence import evidence_search
from brachycal.calibration.robot.identifiability import COMPONENTS
from brachycal.calibration.robot_accuracy import RobotAccuracy
from brachycal.data.formats.touches import read_touch_folder
from brachycal.errors import InputError
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray, skew

#: Starting noise level of the touches (metres): re-estimated from the residuals.
TOUCH_SD_M = 1e-4
#: Default tolerance of a stated distance between points (metres): a printed or machined block.
DISTANCE_SD_M = 5e-5
GROUPS = ("touch", "distance")


@dataclass(frozen=True)
class TouchPlace:
    """The touches of one place.

    Attributes:
        name: the place (a folder name).
        touches: per point, its touches' configurations ``(N_k, nq)`` (radians, the robot's joint order).
        distances: known distances between points, ``{(i, j): metres}``.
        moments: per point, ``(N_k, nq, 3)`` the joints' gravity moments at its touches
            (:func:`~brachycal.calibration.robot.arm_fit.gravity_moments`), for compliance terms.
    """

    name: str
    touches: tuple[FloatArray, ...]
    distances: dict[tuple[int, int], float] = field(default_factory=dict)
    moments: tuple[FloatArray, ...] | None = None


def arm_joints(robot: Robot, flange: str) -> tuple[str, ...]:
    """The joints between the base and ``flange``, in configuration order: the columns of a touch table."""
    selection = ParameterSelection.chain(robot, flange)
    return tuple(name for name, free in zip(robot.joint_names, selection.free[:, 0], strict=True) if free)


def read_places(
    robot: Robot,
    flange: str,
    folders: Sequence[str | os.PathLike[str]],
    distances: dict[tuple[int, int], float] | None = None,
) -> list[TouchPlace]:
    """The places of touch folders (:mod:`brachycal.data.formats.touches`), the tables' columns the
    arm's joints to ``flange``, with ``distances`` (metres) known between the points of each.

    Raises:
        InputError: a folder the reader refuses; two folders of the same name; a distance between
            points a place has not.
    """
    joints = arm_joints(robot, flange)
    out: list[TouchPlace] = []
    for path in folders:
        folder = read_touch_folder(path, joints)
        if any(p.name == folder.name for p in out):
            raise InputError(f"two places are named {folder.name!r}", file=path)
        known = dict(distances or {})
        for i, j in known:
            if max(i, j) >= len(folder.tables):
                raise InputError(
                    f"a distance between points {i} and {j}, but the place has {len(folder.tables)}", file=path
                )
        out.append(TouchPlace(folder.name, tuple(configurations(robot, flange, t) for t in folder.tables), known))
    return out


def configurations(robot: Robot, flange: str, table: FloatArray) -> FloatArray:
    """``(N, nq)`` configurations from a table of the arm's joints (:func:`arm_joints` columns); the
    robot's other joints (a gripper's fingers) at zero."""
    joints = arm_joints(robot, flange)
    table = np.atleast_2d(np.asarray(table, dtype=float))
    if table.shape[1] != len(joints):
        raise InputError(f"a touch has {table.shape[1]} joint values; the arm to {flange!r} has {len(joints)}")
    Q = np.zeros((len(table), robot.nq))
    Q[:, [robot.joint_names.index(j) for j in joints]] = table
    return Q


@dataclass(frozen=True)
class TouchModel:
    """The touches' residuals (:class:`~brachycal.calibration.robot.arm_fit.ResidualModel`).

    ``y = (tip (3), point 0 of place 0 (3), point 1 of place 0, …, compliance k per term)``; rows:
    per touch the tip (deflected by ``G k`` under the compliance terms ``compliant``) minus its
    point (3, group ``touch``), then per known distance ``|p_i − p_j| − d`` (group ``distance``).
    """

    places: tuple[TouchPlace, ...]
    flange: str
    compliant: tuple[tuple[int, int], ...] = ()
    groups: tuple[str, ...] = GROUPS

    def n_points(self) -> int:
        return sum(len(p.touches) for p in self.places)

    def point_slots(self) -> list[list[int]]:
        """Per place, per point: its offset in ``y``."""
        out, at = [], 3
        for place in self.places:
            out.append([at + 3 * k for k in range(len(place.touches))])
            at += 3 * len(place.touches)
        return out

    def y_scale(self) -> FloatArray:
        return np.concatenate([np.full(3 + 3 * self.n_points(), 1e-3), np.full(len(self.compliant), 1e-6)])

    def evaluate(self, robot: Robot, y: FloatArray) -> Evaluation:
        ny, nc = len(y), 6 * robot.nq
        r, J_c, J_y, group = [], [], [], []
        tip = y[:3]
        slots = self.point_slots()
        k0 = 3 + 3 * self.n_points()
        compliance = y[k0:]
        for place, offsets in zip(self.places, slots, strict=True):
            for p_index, (Q, at) in enumerate(zip(place.touches, offsets, strict=True)):
                fp = flange_points(robot, Q, self.flange, tip)
                n = len(Q)
                p = fp.p
                if self.compliant:
                    if place.moments is None:
                        raise InputError(f"place {place.name!r} has no joint moments for the compliance terms")
                    G, Omega = deflection_columns(robot, Q, fp, place.moments[p_index], self.compliant)
                    p = p + G @ compliance
                r.append((p - y[at : at + 3]).reshape(-1))
                J_c.append(fp.J_c.reshape(3 * n, nc))
                block = np.zeros((n, 3, ny))
                block[:, :, :3] = fp.R
                block[:, :, at : at + 3] = -np.eye(3)
                if self.compliant:
                    block[:, :, k0:] = G
                    block[:, :, :3] += skew(Omega @ compliance) @ fp.R
                J_y.append(block.reshape(3 * n, ny))
                group.append(np.zeros(3 * n, dtype=int))
            for (i, j), d in place.distances.items():
                delta = y[offsets[i] : offsets[i] + 3] - y[offsets[j] : offsets[j] + 3]
                length = float(np.linalg.norm(delta))
                u = delta / length
                row = np.zeros(ny)
                row[offsets[i] : offsets[i] + 3] = u
                row[offsets[j] : offsets[j] + 3] = -u
                r.append(np.array([length - d]))
                J_c.append(np.zeros((1, nc)))
                J_y.append(row[None])
                group.append(np.ones(1, dtype=int))
        return Evaluation(np.concatenate(r), np.vstack(J_c), np.vstack(J_y), np.concatenate(group))


@dataclass(frozen=True)
class TouchResult:
    """The arm identified from touches.

    Attributes:
        fit: the arm fit (corrections, posterior, identifiability, noise levels).
        flange: the frame the tip is fixed to.
        tip: ``(3,)`` the tip on the flange (metres, flange frame).
        points: per place, ``(K, 3)`` its points (metres, base frame).
        places: the places' names.
        compliant: the compliance terms ``(j, a)``; compliance: their values (rad per N·m);
        compliance_sd: their prior SDs (``inf``: none).
    """

    fit: ArmFit
    flange: str
    tip: FloatArray
    points: tuple[FloatArray, ...]
    places: tuple[str, ...]
    compliant: tuple[tuple[int, int], ...] = ()
    compliance: FloatArray = field(default_factory=lambda: np.zeros(0))
    compliance_sd: FloatArray = field(default_factory=lambda: np.zeros(0))

    def robot(self, nominal: Robot) -> Robot:
        """The corrected robot (without the tip; :meth:`tool_robot` adds it)."""
        return self.fit.robot(nominal)


def identify_touches(
    nominal: Robot,
    places: Sequence[TouchPlace],
    flange: str,
    accuracy: RobotAccuracy | None,
    *,
    tip: FloatArray | None = None,
    selection: str | ParameterSelection | None = None,
    touch_sd_m: float = TOUCH_SD_M,
    distance_sd_m: float = DISTANCE_SD_M,
    estimate_touch_noise: bool = True,
    compliant: Sequence[tuple[int, int]] = (),
    compliance_sd: float | Sequence[float] = np.inf,
    prior: str = "stated",
    progress: Callable[[int], None] | None = None,
) -> TouchResult:
    """Identify the arm from touches of fixed points (module docstring).

    Args:
        nominal: the robot's URDF.
        places: the touches, per place.
        flange: the frame the tip is fixed to.
        accuracy: the stated accuracy (the corrections' prior); ``None``: none.
        tip: start of the tip in ``flange`` (metres; default its origin).
        selection: ``"chain"`` (every component of every joint to the flange; needs a prior; the
            default with one), ``"base"`` (the corrections the data can see,
            :meth:`ParameterSelection.base_set`; the default without a prior), or the free
            corrections themselves.
        touch_sd_m: the touches' noise level (start, re-estimated unless ``estimate_touch_noise`` is false).
        distance_sd_m: the stated tolerance of the known distances (held).
        compliant: joint compliance terms ``(j, a)`` (:func:`~brachycal.calibration.robot.arm_fit.deflection_columns`),
            fitted with the places' ``moments``; ``compliance_sd``: their prior SD (rad per N·m; one, or
            one per term; none by default).
        prior: ``"stated"``: ``accuracy`` and ``compliance_sd`` are the priors; ``"evidence"``:
            the priors that maximise these touches' evidence (:func:`evidence_prior`, started
            from them; a flat compliance prior starts at :data:`COMPLIANCE_SD_START`), recorded
            in the result's ``fit.accuracy`` and :attr:`TouchResult.compliance_sd`.
        progress: called with 1 after each fit: the evidence search's (their number is not known
            ahead) and the last.

    Raises:
        InputError: a place without two touches of a point, a distance between unknown points.
        DegenerateDataError: the touches do not determine the unknowns.
    """
    places = tuple(places)
    if prior == "evidence":
        if accuracy is None:
            raise InputError("a prior chosen by the evidence needs a stated accuracy to start from")
        start_sd = float(np.max(compliance_sd)) if compliant else np.inf
        chosen_prior = evidence_prior(
            nominal,
            places,
            flange,
            accuracy,
            tip=tip,
            compliant=compliant,
            compliance_sd=start_sd if np.isfinite(start_sd) else COMPLIANCE_SD_START,
            touch_sd_m=touch_sd_m,
            distance_sd_m=distance_sd_m,
            progress=progress,
        )
        accuracy, compliance_sd = chosen_prior.accuracy, chosen_prior.compliance_sd
    elif prior != "stated":
        raise InputError(f"unknown prior {prior!r} (stated, evidence)")
    for place in places:
        for k, Q in enumerate(place.touches):
            if len(Q) < 2:
                raise InputError(f"place {place.name!r}: point {k} has {len(Q)} touch(es); at least 2 are needed")
        for i, j in place.distances:
            if not (0 <= i < len(place.touches) and 0 <= j < len(place.touches) and i != j):
                raise InputError(f"place {place.name!r}: a distance between points {i} and {j}, which it has not")
    model = TouchModel(places, flange, tuple(compliant))
    tip0 = np.zeros(3) if tip is None else np.asarray(tip, dtype=float)
    y0 = [tip0]
    for place in places:
        for Q in place.touches:
            y0.append(flange_points(nominal, Q, flange, tip0).p.mean(axis=0))
    y0.append(np.zeros(len(compliant)))
    y = np.concatenate(y0)
    chosen = ParameterSelection.chain(nominal, flange)
    sigma = {"touch": touch_sd_m, "distance": distance_sd_m}
    if selection is None:
        selection = "chain" if accuracy is not None else "base"
    if isinstance(selection, ParameterSelection):
        chosen = selection
    elif selection == "base":
        evaluation = model.evaluate(nominal, y)
        scale = prior_sd(nominal, accuracy) if accuracy is not None else np.ones(6 * nominal.nq)
        chosen = chosen.base_set(evaluation.J_c, evaluation.J_y, scale)
    elif selection != "chain":
        raise InputError(f"unknown parameter selection {selection!r} (base, chain)")
    term_sd = np.broadcast_to(np.asarray(compliance_sd, dtype=float), (len(compliant),)).copy()
    fit = fit_arm(
        nominal,
        model,
        y,
        chosen,
        sigma,
        accuracy,
        estimate_noise=("touch",) if estimate_touch_noise else (),
        y_prior_sd=np.concatenate([np.full(len(y) - len(compliant), np.inf), term_sd]),
    )
    if progress is not None:
        progress(1)
    slots = model.point_slots()
    points = tuple(np.array([fit.y[at : at + 3] for at in offsets]) for offsets in slots)
    k0 = 3 + 3 * model.n_points()
    return TouchResult(
        fit,
        flange,
        fit.y[:3].copy(),
        points,
        tuple(p.name for p in places),
        tuple(compliant),
        fit.y[k0:].copy(),
        term_sd,
    )


#: Start of the compliance terms' prior SD in the evidence search (rad per N·m): a joint
#: stiffness of ~3e4 N·m/rad, a harmonic drive's with its torque sensor.
COMPLIANCE_SD_START = 3e-5


@dataclass(frozen=True)
class EvidencePrior:
    """The prior the touches' evidence chose (:func:`evidence_prior`).

    Attributes:
        accuracy: per-joint translation and rotation SDs (the encoder SD kept from the start).
        compliance_sd: the compliance terms' prior SD (rad per N·m; ``inf`` without terms).
        log_evidence: the touches' log evidence at the choice (:attr:`ArmFit.log_evidence`).
        evaluations: fits the search took.
    """

    accuracy: RobotAccuracy
    compliance_sd: float
    log_evidence: float
    evaluations: int


def evidence_prior(
    nominal: Robot,
    places: Sequence[TouchPlace],
    flange: str,
    start: RobotAccuracy,
    *,
    tip: FloatArray | None = None,
    compliant: Sequence[tuple[int, int]] = (),
    compliance_sd: float = COMPLIANCE_SD_START,
    touch_sd_m: float = TOUCH_SD_M,
    distance_sd_m: float = DISTANCE_SD_M,
    progress: Callable[[int], None] | None = None,
) -> EvidencePrior:
    """The prior SDs that maximise the evidence of ``places``' touches (type-II maximum likelihood).

    The per-joint translation and rotation SDs of the corrections (``"chain"`` selection), the axis
    tilt's SD when ``start`` states one (:attr:`RobotAccuracy.tilt_sd_rad`) and, with compliance
    terms, their common SD are the hyper-parameters; the touch noise is re-estimated in each fit
    (its own evidence maximum). :func:`~brachycal.calibration.robot.evidence.evidence_search` from
    ``start`` (and ``compliance_sd``). Only the touches given enter: the choice is the training
    data's own. ``progress``: called with 1 after each fit.

    Raises:
        InputError, DegenerateDataError: as :func:`identify_touches` at the start.
    """
    terms = tuple(compliant)

    def log_evidence(accuracy: RobotAccuracy, extra: tuple[float, ...]) -> float:
        return identify_touches(
            nominal,
            places,
            flange,
            accuracy,
            tip=tip,
            selection="chain",
            touch_sd_m=touch_sd_m,
            distance_sd_m=distance_sd_m,
            compliant=terms,
            compliance_sd=extra[0] if terms else np.inf,
        ).fit.log_evidence

    found = evidence_search(
        log_evidence,
        start,
        (compliance_sd,) if terms else (),
        source="chosen by the evidence of the training touches",
        data="the touches",
        progress=progress,
    )
    return EvidencePrior(found.accuracy, found.extra[0] if terms else np.inf, found.log_evidence, found.evaluations)


#: The settings ``prior="choose"`` scores, the default first (:func:`choose_touch_setting`):
#: the stated accuracy; the per-joint SDs by the evidence; the same with the axes' tilt apart.
TOUCH_SETTINGS = ("stated", "evidence", "evidence+tilt")
#: Folds of the training touches' cross-validation: each point's touches in contiguous blocks
#: (postures recorded one after the other are alike: a block leaves its neighbours out with it).
CV_FOLDS = 5
#: Touches of each point a fold's fit keeps at least (a block of ``N / folds`` left out).
MIN_FOLD_TOUCHES = 2


def setting_prior(setting: str, accuracy: RobotAccuracy) -> tuple[str, RobotAccuracy]:
    """The prior rule and the (start) accuracy of a :data:`TOUCH_SETTINGS` setting, from the stated ``accuracy``."""
    if setting == "stated":
        return "stated", accuracy
    if setting == "evidence":
        return "evidence", replace(accuracy, tilt_sd_rad=None)
    if setting == "evidence+tilt":
        tilt = accuracy.tilt_sd_rad if accuracy.tilt_sd_rad is not None else accuracy.rotation_sd_rad
        return "evidence", replace(accuracy, tilt_sd_rad=tilt)
    raise InputError(f"unknown setting {setting!r} ({', '.join(TOUCH_SETTINGS)})")


def touch_cv_errors(
    nominal: Robot,
    places: Sequence[TouchPlace],
    flange: str,
    accuracy: RobotAccuracy,
    *,
    setting: str = "stated",
    over: str = "places",
    tip: FloatArray | None = None,
    folds: int = CV_FOLDS,
    progress: Callable[[int], None] | None = None,
) -> tuple[FloatArray, np.ndarray]:
    """Cross-validation of a setting inside ``places`` (the training touches). Each fit is of the
    geometry (no compliance: what a URDF holds), with the setting's prior (:func:`setting_prior`).

    ``over="places"`` (two places at least): each place is predicted by the fit of the others, as a
    held-out place is judged: a touch's error is the distance of its tip (forward kinematics on
    that fit's robot and tip) from the mean tip of its point (MUKCa's figure, per touch).
    ``over="postures"``: each point's touches cut into ``folds`` contiguous blocks, fold ``f``
    fitted on all but the ``f``-th; a left-out touch's error is the distance of its tip from its
    point as the fold fitted it. ``progress``: called with 1 after each fit (:func:`identify_touches`).

    Returns:
        ``(errors_m, block)``: per left-out touch its error (metres) and its block's number (per
        place, point and contiguous ``folds``-th of its touches): the units of the paired
        comparison's standard error (neighbouring touches are alike: not independent).

    Raises:
        InputError: fewer than two places over places; a point with fewer than ``folds`` +
            :data:`MIN_FOLD_TOUCHES` touches; a setting not in :data:`TOUCH_SETTINGS`.
    """
    prior, start = setting_prior(setting, accuracy)
    if over not in ("places", "postures"):
        raise InputError(f"unknown cross-validation {over!r} (places, postures)")
    if over == "places" and len(places) < 2:
        raise InputError("cross-validation over places needs two training places at least")
    cuts = []
    for place in places:
        for k, Q in enumerate(place.touches):
            if len(Q) < folds + MIN_FOLD_TOUCHES:
                raise InputError(
                    f"place {place.name!r}: point {k} has {len(Q)} touches; {folds + MIN_FOLD_TOUCHES} "
                    f"are needed to choose the setting by cross-validation"
                )
            cuts.append(np.array_split(np.arange(len(Q)), folds))
    block = np.concatenate(
        [np.repeat(at * folds + np.arange(folds), [len(c) for c in cut]) for at, cut in enumerate(cuts)]
    )
    errors = []
    if over == "places":
        for i, place in enumerate(places):
            others = [p for j, p in enumerate(places) if j != i]
            fit = identify_touches(
                nominal, others, flange, start, tip=tip, selection="chain", prior=prior, progress=progress
            )
            robot = fit.robot(nominal)
            for Q in place.touches:
                p = flange_points(robot, Q, flange, fit.tip).p
                errors.append(np.linalg.norm(p - p.mean(axis=0), axis=1))
        return np.concatenate(errors), block
    held: list[list[FloatArray]] = [[np.zeros(0)] * folds for _ in cuts]
    for f in range(folds):
        at, kept = 0, []
        for place in places:
            kept.append(
                TouchPlace(
                    place.name,
                    tuple(np.delete(Q, cuts[at + k][f], axis=0) for k, Q in enumerate(place.touches)),
                    place.distances,
                )
            )
            at += len(place.touches)
        fit = identify_touches(nominal, kept, flange, start, tip=tip, selection="chain", prior=prior, progress=progress)
        robot = fit.robot(nominal)
        at = 0
        for p_index, place in enumerate(places):
            for k, Q in enumerate(place.touches):
                p = flange_points(robot, Q[cuts[at][f]], flange, fit.tip).p
                held[at][f] = np.linalg.norm(p - fit.points[p_index][k], axis=1)
                at += 1
    return np.concatenate([e for point in held for e in point]), block


@dataclass(frozen=True)
class SettingScore:
    """One setting's cross-validation inside the training touches (:func:`touch_cv_errors`).

    Attributes:
        setting: its name (:data:`TOUCH_SETTINGS`).
        cv_error_mm: the left-out touches' mean error (mm; :func:`touch_cv_errors`).
        vs_chosen: against the setting chosen before it, the mean paired difference of the
            left-out touches' distances (mm; negative: better) and its standard error (over the
            blocks); ``None`` for the first.
    """

    setting: str
    cv_error_mm: float
    vs_chosen: tuple[float, float] | None = None


@dataclass(frozen=True)
class SettingChoice:
    """The setting the training touches chose (:func:`choose_touch_setting`), and why.

    Attributes:
        scores: each setting's cross-validation (none when there was none: one training place).
        chosen: the setting (:data:`TOUCH_SETTINGS`).
        reason: why, in words.
        over: what the cross-validation left out: ``"places"``, ``"postures"``, or ``"none"``.
    """

    scores: tuple[SettingScore, ...]
    chosen: str
    reason: str
    over: str

    def rule(self) -> str:
        if self.over == "none":
            return "no cross-validation (one training place): the defaults"
        if self.over == "places":
            what = "leave-one-place-out over the training places"
        else:
            what = f"{CV_FOLDS}-fold cross-validation over the training touches' postures"
        return (
            f"{what}; a setting replaces the one chosen before it only if better by more than the "
            "standard error of the paired differences"
        )

    def as_json(self) -> dict[str, object]:
        return {
            "rule": self.rule(),
            "scores": {
                s.setting: {
                    "cv_error_mm": s.cv_error_mm,
                    "vs_previous_choice_mm": None if s.vs_chosen is None else list(s.vs_chosen),
                }
                for s in self.scores
            },
            "chosen": self.chosen,
            "reason": self.reason,
        }

    def summary(self) -> list[str]:
        lines = [f"setting: {self.chosen} ({self.reason}; {self.rule()})"]
        lines += [f"  {s.setting:14s} cross-validated tip error {s.cv_error_mm:.4f} mm" for s in self.scores]
        return lines


def choose_touch_setting(
    nominal: Robot,
    places: Sequence[TouchPlace],
    flange: str,
    accuracy: RobotAccuracy,
    *,
    tip: FloatArray | None = None,
    settings: Sequence[str] = TOUCH_SETTINGS,
    over: str | None = None,
    progress: Callable[[int], None] | None = None,
) -> SettingChoice:
    """The setting (of ``settings``, the first the default) the training touches ``places``
    support: each scored by :func:`touch_cv_errors` ``over`` places (the default with two training
    places or more), and taken in turn in place of the one chosen before it only if its left-out
    touches' errors are lower by more than the standard error of the paired differences (of the
    blocks' means: touches of one block are not independent). With one training place (and
    ``over`` not given) the first setting, unscored: on MUKCa's Pandas, the postures of one place
    prefer priors that do worse at other places (``benchmarks/mukca.py --choose``). Only the
    touches given enter; held-out places never do."""
    if over is None:
        over = "places" if len(places) >= 2 else "none"
    if over == "none":
        reason = f"{settings[0]}: the default; one training place cannot tell how a setting does at other places"
        return SettingChoice((), settings[0], reason, "none")
    scores: list[SettingScore] = []
    chosen, chosen_e, reasons = "", np.zeros(0), []
    for setting in settings:
        e, block = touch_cv_errors(
            nominal, places, flange, accuracy, setting=setting, over=over, tip=tip, progress=progress
        )
        versus = None
        if not chosen:
            chosen, chosen_e = setting, e
            reasons.append(f"{setting}: the default")
        else:
            d = np.array([np.mean((e - chosen_e)[block == b]) for b in np.unique(block)]) * 1e3
            mean, se = float(np.mean(d)), float(np.std(d, ddof=1) / np.sqrt(len(d)))
            versus = (mean, se)
            if mean < -se:
                reasons.append(f"{setting} beats {chosen} by {-mean:.4f} ± {se:.4f} mm")
                chosen, chosen_e = setting, e
            else:
                reasons.append(f"{setting} not better than {chosen} by more than its SE ({mean:+.4f} ± {se:.4f} mm)")
        scores.append(SettingScore(setting, float(np.mean(e)) * 1e3, versus))
    return SettingChoice(tuple(scores), chosen, "; ".join(reasons), over)


@dataclass(frozen=True)
class TouchScatter:
    """MUKCa's figures of one place.

    Attributes:
        scatter_m: per point, the mean distance of the tips from their mean (metres).
        distance_error_m: ``{(i, j): | |p̄_i − p̄_j| − d |}`` for the known distances (metres).
    """

    scatter_m: FloatArray
    distance_error_m: dict[tuple[int, int], float]

    @property
    def mean_scatter_m(self) -> float:
        """The scatter averaged over the points (MUKCa's "mean absolute error")."""
        return float(np.mean(self.scatter_m))


def touch_scatter(
    robot: Robot,
    place: TouchPlace,
    flange: str,
    tip: FloatArray,
    compliant: Sequence[tuple[int, int]] = (),
    compliance: FloatArray | None = None,
) -> TouchScatter:
    """MUKCa's figures of ``place`` on ``robot`` with the tip ``tip`` (metres in ``flange``)."""
    means, scatter = [], []
    for k, Q in enumerate(place.touches):
        fp = flange_points(robot, Q, flange, tip)
        p = fp.p
        if compliant:
            if place.moments is None or compliance is None:
                raise InputError(f"place {place.name!r} has no joint moments for the compliance terms")
            p = p + deflection_columns(robot, Q, fp, place.moments[k], compliant)[0] @ compliance
        means.append(p.mean(axis=0))
        scatter.append(float(np.mean(np.linalg.norm(p - means[-1], axis=1))))
    errors = {(i, j): abs(float(np.linalg.norm(means[i] - means[j])) - d) for (i, j), d in place.distances.items()}
    return TouchScatter(np.array(scatter), errors)


@dataclass(frozen=True)
class TouchReport:
    """A touch identification judged place by place: what ``brachycal robot identify touches`` reports.

    Attributes:
        result: the identification (trained on :attr:`train`).
        train: the training places' names.
        nominal: per place, MUKCa's figures on the nominal URDF with its tool frame.
        identified: per place, on the identified robot with the identified tip (and compliance).
        geometry_only: per place, what the written URDF alone gives (:attr:`urdf_result`'s robot
            and tip); equal to :attr:`identified` without compliance.
        tool_frame: the URDF frame of the touching tip.
        urdf_fit: with compliance, the same identification without it: the best geometry a URDF
            can carry (the compliance fit's geometry has absorbed nothing of what compliance
            explains, so alone it does worse); None without compliance.
        choice: with ``prior="choose"``, the setting the training touches chose and why.
    """

    result: TouchResult
    train: tuple[str, ...]
    nominal: dict[str, TouchScatter]
    identified: dict[str, TouchScatter]
    geometry_only: dict[str, TouchScatter]
    tool_frame: str
    urdf_fit: TouchResult | None = None
    choice: SettingChoice | None = None

    @property
    def urdf_result(self) -> TouchResult:
        """The identification the written URDF carries: :attr:`urdf_fit`, or :attr:`result`."""
        return self.urdf_fit if self.urdf_fit is not None else self.result

    @property
    def held_out(self) -> list[str]:
        return [name for name in self.nominal if name not in self.train]

    def headline(self) -> dict[str, float | None]:
        """The held-out places' mean tip scatter (mm): of the written URDF (the headline: what the
        user gets), of the nominal URDF, and with compliance (not in the URDF; ``None`` without
        it). All ``None`` without held-out places."""
        held = self.held_out

        def mean(scores: dict[str, TouchScatter]) -> float | None:
            return float(np.mean([scores[n].mean_scatter_m for n in held])) * 1e3 if held else None

        return {
            "written_urdf_mm": mean(self.geometry_only),
            "nominal_urdf_mm": mean(self.nominal),
            "with_compliance_not_in_urdf_mm": mean(self.identified) if self.result.compliant else None,
        }

    def calibrated_robot(self, nominal: Robot) -> Robot:
        """The corrected robot (:attr:`urdf_result`, geometry only) with the identified tip
        written into the tool frame's fixed joint."""
        urdf = self.urdf_result
        parent, T_parent_tool = nominal.tool_transform(self.tool_frame)
        T_flange_parent = nominal.transform(urdf.flange, parent, np.zeros(nominal.nq))
        T = T_parent_tool.copy()
        T[:3, 3] = np.linalg.solve(T_flange_parent[:3, :3], urdf.tip - T_flange_parent[:3, 3])
        return urdf.robot(nominal).with_tool_transform(self.tool_frame, T)

    def as_json(self) -> dict[str, object]:
        def figures(scores: dict[str, TouchScatter]) -> dict[str, object]:
            return {
                name: {
                    "scatter_mm": s.mean_scatter_m * 1e3,
                    "distance_error_mm": {f"{i}-{j}": e * 1e3 for (i, j), e in s.distance_error_m.items()},
                }
                for name, s in scores.items()
            }

        def corrections(fit: ArmFit) -> dict[str, dict[str, float]]:
            return {
                name: dict(zip(COMPONENTS, map(float, c), strict=True))
                for name, c in zip(fit.joint_names, fit.corrections, strict=True)
            }

        written = self.urdf_result  # what robot.urdf carries: every top-level figure is its
        fit = written.fit
        compliant = None if self.urdf_fit is None else self.result
        return {
            "protocol": "touches of fixed points",
            "headline": {
                "figure": "the held-out places' mean tip scatter (MUKCa's figure), mm",
                **self.headline(),
            },
            "setting_choice": None if self.choice is None else self.choice.as_json(),
            "train": list(self.train),
            "held_out": list(self.held_out),
            "flange": written.flange,
            "tool_frame": self.tool_frame,
            "tip_m": written.tip.tolist(),
            "tip_sd_m": np.sqrt(np.diag(fit.y_covariance())[:3]).tolist(),
            "touch_noise_sd_m": fit.sigma["touch"],
            "corrections": corrections(fit),
            "parameterisation": "per joint origin: T_parent_joint <- T_parent_joint @ T(exp(w), v); metres, radians",
            "free_corrections": fit.selection.names,
            "prior": fit.accuracy.as_json() if fit.accuracy is not None else None,
            "log_evidence": fit.log_evidence,
            "identified_combinations": fit.identifiability.identified,
            "structural_rank": fit.identifiability.structural_rank,
            "nominal": figures(self.nominal),
            "identified": figures(self.identified),
            "urdf_only": figures(self.geometry_only),
            "with_compliance": None
            if compliant is None
            else {
                "note": "joint compliance under gravity: no URDF holds it; robot.urdf is the fit above",
                "tip_m": compliant.tip.tolist(),
                "touch_noise_sd_m": compliant.fit.sigma["touch"],
                "corrections": corrections(compliant.fit),
                "compliance_rad_per_nm": {
                    f"{compliant.fit.joint_names[j]}.{'xyz'[a]}": float(k)
                    for (j, a), k in zip(compliant.compliant, compliant.compliance, strict=True)
                },
                "compliance_prior_sd_rad_per_nm": [
                    float(v) if np.isfinite(v) else None for v in compliant.compliance_sd
                ],
                "log_evidence": compliant.fit.log_evidence,
            },
        }


def identify_touch_folders(
    nominal: Robot,
    folders: Sequence[str | os.PathLike[str]],
    tool_frame: str,
    train: Sequence[str],
    accuracy: RobotAccuracy,
    *,
    distance_m: float | None = None,
    dynamics: Robot | None = None,
    prior: str = "stated",
    progress: Callable[[int], None] | None = None,
) -> TouchReport:
    """Identify ``nominal`` from the touch folders ``train`` names and judge it on every place.

    Args:
        nominal: the robot's URDF; ``tool_frame`` is the touching tip's frame in it (fixed to the
            flange, its link: the start of the tip, and where the identified tip is written).
        folders: place folders (:mod:`brachycal.data.formats.touches`).
        train: the places (folder names) to identify from; the others are held out.
        accuracy: the stated accuracy (the prior).
        distance_m: the known distance between points 0 and 1 of every place (None: unknown).
        dynamics: a URDF of the same arm with masses: joint compliance under gravity is fitted
            (each revolute arm joint that gravity loads, about its axis), and the geometry alone
            once more for the URDF (:attr:`TouchReport.urdf_fit`).
        prior: ``"stated"`` (``accuracy``, compliance free) or ``"evidence"``: chosen by the
            training places' evidence (:func:`evidence_prior`; the held-out places never enter);
            ``"choose"``: the setting of :data:`TOUCH_SETTINGS` the training touches' own
            cross-validation supports (:func:`choose_touch_setting`; :attr:`TouchReport.choice`).
        progress: called with 1 after each fit (:func:`identify_touches`; with the evidence their
            number is not known ahead: tens per search, one search per fit of :attr:`TouchReport.result`
            and :attr:`TouchReport.urdf_fit`).

    Raises:
        InputError: a folder the reader refuses, a training place not among them, a tool frame
            not fixed to a link; ``dynamics`` not the same arm or without masses
            (:func:`~brachycal.calibration.robot.arm_fit.check_dynamics`).
    """
    flange, T_flange_tool = nominal.tool_transform(tool_frame)
    # The tip's link may be several fixed joints from the last moving one: the tip lives in it.
    distances = {(0, 1): float(distance_m)} if distance_m is not None else {}
    places = read_places(nominal, flange, folders, distances)
    names = [p.name for p in places]
    for name in train:
        if name not in names:
            raise InputError(f"training place {name!r} is not among the folders ({', '.join(names)})")
    if len(set(train)) != len(train):
        raise InputError("a training place is named twice")
    compliant: tuple[tuple[int, int], ...] = ()
    if dynamics is not None:
        check_dynamics(dynamics, nominal, arm_joints(nominal, flange))
        places = [
            TouchPlace(p.name, p.touches, p.distances, tuple(gravity_moments(dynamics, nominal, Q) for Q in p.touches))
            for p in places
        ]
        compliant = _loaded_joints(nominal, flange, [p for p in places if p.name in train])
    fit_places = [p for p in places if p.name in train]
    tip0 = T_flange_tool[:3, 3]
    choice = None
    if prior == "choose":
        choice = choose_touch_setting(nominal, fit_places, flange, accuracy, tip=tip0, progress=progress)
        prior, accuracy = setting_prior(choice.chosen, accuracy)

    def identify(terms: tuple[tuple[int, int], ...]) -> TouchResult:
        return identify_touches(
            nominal,
            fit_places,
            flange,
            accuracy,
            tip=tip0,
            selection="chain",
            compliant=terms,
            prior=prior,
            progress=progress,
        )

    result = identify(compliant)
    robot = result.robot(nominal)
    identified = {
        p.name: touch_scatter(robot, p, flange, result.tip, result.compliant, result.compliance) for p in places
    }
    urdf_fit = identify(()) if compliant else None
    geometry_only = identified  # without compliance the written URDF is the fit itself
    if urdf_fit is not None:
        urdf_robot = urdf_fit.robot(nominal)
        geometry_only = {p.name: touch_scatter(urdf_robot, p, flange, urdf_fit.tip) for p in places}
    return TouchReport(
        result,
        tuple(train),
        {p.name: touch_scatter(nominal, p, flange, tip0) for p in places},
        identified,
        geometry_only,
        tool_frame,
        urdf_fit,
        choice,
    )


#: A joint is compliant under gravity in the fit when its RMS gravity torque over the training
#: touches reaches this fraction of the most loaded joint's (a vertical first axis carries none).
LOADED_FRACTION = 1e-3


def _loaded_joints(robot: Robot, flange: str, places: Sequence[TouchPlace]) -> tuple[tuple[int, int], ...]:
    """``(j, a)`` terms of the revolute arm joints whose gravity torque about their axis is not negligible."""
    joints = [robot.joint_names.index(n) for n in arm_joints(robot, flange) if robot.joint_kinds[n] != "prismatic"]
    rms = {}
    for j in joints:
        axis = robot.joint_axis(robot.joint_names[j])
        torques = np.concatenate([m[:, j] @ axis for p in places for m in (p.moments or ())])
        rms[j] = float(np.sqrt(np.mean(torques**2))) if torques.size else 0.0
    top = max(rms.values(), default=0.0)
    terms = []
    for j in joints:
        if top > 0 and rms[j] >= LOADED_FRACTION * top:
            axis = np.abs(robot.joint_axis(robot.joint_names[j]))
            terms.append((j, int(np.argmax(axis))))
    return tuple(terms)
