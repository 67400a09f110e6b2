"""The demo: the paper's calibration of a digital-twin session, judged against the twin's truth.

What ``brachycal demo`` runs (:func:`run_demo`): a twin session with the paper's set-up is
simulated (or the committed example is read), its files are written, the session is calibrated
*from those files* as a lab would (so the files are what the numbers come from), and the
calibration is judged by the end-to-end targeting error of every method on the same simulated
robot, next to the tracker route (N-wire phantom + hand–eye with an optical tracker, Table III).
The returned :class:`DemoRun` holds everything the tables and figures show
(:mod:`brachycal.reporting.demo_report` renders them).

Any robot with a description (``robot.rig``): the twin plans in its workspace, touches and moves
with its arms; the committed example is the SDA10F's only.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from brachycal.calibration.chain import fit_chain, select_model
from brachycal.calibration.metrics import ErrorStats
from brachycal.calibration.result import Calibration
from brachycal.calibration.sequential.image_to_probe import METHODS
from brachycal.calibration.sequential.method import SequentialResult, calibrate, loo_points
from brachycal.calibration.session.result_file import write_result
from brachycal.data.session import FILES as SESSION_FILES
from brachycal.data.session import Session, read_session
from brachycal.errors import InputError
from brachycal.imaging.pixels import image_points
from brachycal.io import OutputSet, bundled, output_set
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray, inverse, transform_points
from brachycal.simulation.twin import Twin, TwinConfig, simulate
from brachycal.simulation.twin_files import read_twin, write_twin
from brachycal.studies.nwire_twin import T_PTIP_MARKER, NWireSimConfig, tracker_route
from brachycal.studies.phantom_twin import phantom_route
from brachycal.studies.targeting import TargetingResult, targeting_error

#: The method whose leave-one-out points the demo's figures show (Figs. 10 and 11).
FIGURE_METHOD = "icp"
#: What :func:`run_demo` does in turn, each reported to its ``progress`` when done: the session
#: simulated (or read) and written, calibrated from its files, judged against the truth.
DEMO_STAGES = ("session", "calibration", "targeting")
#: The methods whose calibrated image frame the demo compares with the truth.
TRUTH_METHODS = ("kabsch", "scaled_uv")


@dataclass(frozen=True)
class DemoRun:
    """A demo's session, calibration and judgement (SI units; ``base_link`` unless said).

    Attributes:
        origin: where the session came from, in words (a seed, or the committed example).
        twin: the simulated session with its truth.
        session: the session as read back from the files written (what was calibrated).
        result: the sequential calibration of it.
        n_targets: targets of the targeting error.
        targeting: method → its end-to-end targeting error.
        tracking: the tracker route's settings.
        tracker: the tracker route's targeting error (Table III).
        loo_real_m, loo_cal_m: ``(N, 3)`` ``figure_method``'s leave-one-out points.
        figure_method: the method the figures show: :data:`FIGURE_METHOD`, or the first method
            calibrated if it refused the session (``result.refused``).
    """

    origin: str
    twin: Twin
    session: Session
    result: SequentialResult
    n_targets: int
    targeting: dict[str, TargetingResult]
    tracking: NWireSimConfig
    tracker: TargetingResult
    loo_real_m: FloatArray
    loo_cal_m: FloatArray
    figure_method: str = FIGURE_METHOD

    def tip_errors_m(self) -> tuple[FloatArray, FloatArray]:
        """``(3,)`` needle tip and ``(3,)`` probe tip, calibrated minus true, on their flanges."""
        truth, result = self.twin.truth, self.result
        return result.T_ER_Ntip[:3, 3] - truth.T_ER_Ntip[:3, 3], result.T_EL_Ptip[:3, 3] - truth.T_EL_Ptip[:3, 3]

    def image_centre_error_m(self, method: str) -> FloatArray:
        """``(3,)`` where ``method`` puts the planned cube centre's pixel on the left flange, minus the truth.

        A secondary figure: a calibration rightly absorbs part of the robot's own error, so it
        need not reproduce the true transforms to target well.
        """
        truth, image = self.twin.truth, self.result.image[method]
        centre_px = self.twin.config.spec.centre_px
        calibrated = transform_points(self.result.T_EL_Ptip @ image.T_Ptip_I, image_points(centre_px, image.spacing_m))
        true = transform_points(truth.T_EL_Ptip @ truth.T_Ptip_I, image_points(centre_px, truth.spacing_m))
        return (calibrated - true)[0]


def check_example_robot(robot: Robot) -> None:
    """Refuse the committed example (``examples/twin_session``, simulated on the SDA10F) for another robot.

    Raises:
        InputError: ``robot`` is not the SDA10F.
    """
    name = robot.rig.name
    if name != "sda10f":
        raise InputError(
            f"the committed example examples/twin_session is the SDA10F's, not {name!r}'s: "
            "simulate one instead (drop --example)"
        )


@contextmanager
def _as_written(outputs: OutputSet, session_dir: Path) -> Iterator[Path]:
    """A temporary folder showing the staged session files under their own names (symlinks)."""
    with tempfile.TemporaryDirectory(prefix="brachycal-demo-") as tmp:
        for name in SESSION_FILES:
            os.symlink(outputs.path(session_dir / name).absolute(), Path(tmp) / name)
        yield Path(tmp)


def run_demo(
    robot: Robot,
    folder: str | os.PathLike[str],
    *,
    seed: int = 0,
    example: bool = False,
    n_targets: int = 50,
    force: bool = False,
    outputs: OutputSet | None = None,
    progress: Callable[[int], object] | None = None,
) -> DemoRun:
    """Simulate (or read) a twin session, write it, calibrate it from its files, judge it.

    Writes ``folder/session`` (the session, ``truth.json`` and ``physical_robot.urdf``:
    :data:`~brachycal.simulation.twin_files.TWIN_FILES`) and ``folder/result.json``. All or
    nothing: with ``outputs`` (a command's :class:`~brachycal.io.OutputSet`) the files join
    that set and are committed with it; without, they are committed together on return.

    Args:
        robot: the nominal model (the software's).
        folder: where the session and the result go.
        seed: the simulated session's seed (ignored with ``example``).
        example: calibrate the committed ``examples/twin_session`` (seed 0, the SDA10F's) instead.
        n_targets: targets of the targeting error.
        force: replace existing files.
        progress: called with 1 after each of the :data:`DEMO_STAGES`.

    Raises:
        SolverError: a pose of the set-up is unreachable for the simulated robot.
        OutputError: a file cannot be written.
        InputError: ``example`` with a robot other than the SDA10F.
    """
    folder = Path(folder)
    rig = robot.rig
    if example:
        check_example_robot(robot)
        twin = read_twin(bundled("examples", "twin_session"), robot)
        origin = "the committed example examples/twin_session"
    else:
        twin = simulate(robot, TwinConfig(seed=seed))
        origin = (
            f"a simulated session (seed {seed})"
            if rig.name == "sda10f"
            else f"a simulated {rig.name} session (seed {seed})"
        )
    session_dir = folder / "session"

    def done() -> None:
        if progress is not None:
            progress(1)

    with output_set(outputs, force=force) as out:
        write_twin(twin, session_dir, force=force, outputs=out)
        done()
        # Calibrate from the files as written (the staged ones: the same bytes the folder will hold).
        with _as_written(out, session_dir) as written:
            session = read_session(written, robot)
        result = calibrate(session, robot)
        write_result(result, out.path(folder / "result.json", make_parents=True), force=force, robot=robot)
        done()
    # A method that refused the session has no calibration to judge (Table II says why).
    targeting = {m: targeting_error(twin, result.calibration(m), n_targets) for m in METHODS if m in result.image}
    tracking = NWireSimConfig(seed=twin.config.seed)
    route = tracker_route(twin, tracking)
    tracker = targeting_error(twin, Calibration(result.T_ER_Ntip, route.T_EL_marker, route.image), n_targets)
    figure = FIGURE_METHOD if FIGURE_METHOD in result.image else next(iter(result.image))
    p_real, p_cal = loo_points(session, robot, result, figure)
    done()
    return DemoRun(origin, twin, session, result, n_targets, targeting, tracking, tracker, p_real, p_cal, figure)


#: Table III's rows in order: label → the paper's figure beside it (MAE of the whole system, mm,
#: Table III; Shen et al.'s is their image calibration's accuracy, as the paper quotes it in §IV).
TABLE3_PAPER: dict[str, str] = {
    "ICP (paper's fusion)": "0.67",
    "Kabsch (paper's fusion)": "0.72",
    "Landmark/Horn (paper's fusion)": "0.72",
    "Whole chain (brachycal)": "-",
    "N-wire + tracker": "3.51",
    "Multi-wedge + tracker": "3.11",
    "Arbitrary wire + tracker": "1.022 ± 0.085 (image only)",
}
_FUSION_ROWS = {
    "icp": "ICP (paper's fusion)",
    "kabsch": "Kabsch (paper's fusion)",
    "horn": "Landmark/Horn (paper's fusion)",
}
_PHANTOM_ROWS = {"wedge": "Multi-wedge + tracker", "wire": "Arbitrary wire + tracker"}
#: The phantom routes' image calibration alone (what Shen et al. report): its label per route.
TABLE3_IMAGE: dict[str, str] = {
    "N-wire + tracker": "N-wire, image alone",
    "Multi-wedge + tracker": "Multi-wedge, image alone",
    "Arbitrary wire + tracker": "Arbitrary wire, image alone",
}


@dataclass(frozen=True)
class Table3:
    """Table III on the twin: per method, the whole-system targeting MAE (mm) of every seed.

    Attributes:
        seeds: the twin's seeds. n_targets: targets per seed.
        maes_mm: row label (:data:`TABLE3_PAPER`) → ``(len(seeds),)`` MAEs, mm.
        chain_models: the whole chain's image model chosen per seed (empty without the chain).
        image_mm: label (:data:`TABLE3_IMAGE`) → ``(len(seeds),)`` mean error of a phantom route's
            image calibration alone, mm: where it puts the targets' pixels on the marker body
            against the truth (no robot, no hand–eye).
    """

    seeds: tuple[int, ...]
    n_targets: int
    maes_mm: dict[str, list[float]]
    chain_models: tuple[str, ...]
    image_mm: dict[str, list[float]] = field(default_factory=dict)

    @classmethod
    def from_rows(
        cls, seeds: Sequence[int], n_targets: int, rows: dict[str, list[float]], chain_models: Sequence[str]
    ) -> Table3:
        """Split per-seed values by label (:func:`table3_twin`'s keys) into the two parts of the table."""
        image = set(TABLE3_IMAGE.values())
        return cls(
            tuple(seeds),
            n_targets,
            {k: v for k, v in rows.items() if k not in image},
            tuple(chain_models),
            {k: v for k, v in rows.items() if k in image},
        )


def table3_seed(
    robot: Robot, seed: int, n_targets: int = 50, chain: bool = True
) -> tuple[dict[str, float], str | None]:
    """One seed of Table III: every method's targeting MAE (mm) on the same simulated robot, and the chain's model."""
    row, model, _ = table3_twin(robot, simulate(robot, TwinConfig(seed=seed)), n_targets, chain)
    return row, model


def table3_twin(
    robot: Robot, twin: Twin, n_targets: int = 50, chain: bool = True
) -> tuple[dict[str, float], str | None, SequentialResult]:
    """Table III's row values on one twin: MAEs (mm) by :data:`TABLE3_PAPER` label and the phantom
    routes' image errors alone (mm, :data:`TABLE3_IMAGE` labels), the chain's image model (None
    without the chain), and the fusion calibration (its needle tip serves the tracker routes too).

    The fusion methods and the chain calibrate the twin's session; the three phantom routes share
    the N-wire route's hand–eye estimate (:func:`~brachycal.studies.phantom_twin.phantom_route`),
    so they differ only in their phantom. The tracker settings are
    :class:`~brachycal.studies.nwire_twin.NWireSimConfig`'s defaults with the twin's seed.
    """
    seed = twin.config.seed
    result = calibrate(twin.session, robot, ("icp", "kabsch", "horn"))

    def mae(T_ER_Ntip: FloatArray, T_EL_probe: FloatArray, image) -> float:
        return targeting_error(twin, Calibration(T_ER_Ntip, T_EL_probe, image), n_targets).stats.mae_mm

    # A fusion method that refused this seed's session has no targeting error: NaN, left out of the means.
    row = {
        label: mae(result.T_ER_Ntip, result.T_EL_Ptip, result.image[m]) if m in result.image else float("nan")
        for m, label in _FUSION_ROWS.items()
    }
    model = None
    if chain:
        model = select_model(twin.session, robot, result).model
        fit = fit_chain(twin.session, robot, result, model)
        row["Whole chain (brachycal)"] = mae(fit.T_ER_Ntip, fit.T_EL_Ptip, fit.image)
    sim = NWireSimConfig(seed=seed)
    route = tracker_route(twin, sim)
    routes = {"N-wire + tracker": route}
    for method, label in _PHANTOM_ROWS.items():
        routes[label] = phantom_route(twin, method, sim, T_EL_marker=route.T_EL_marker)
    truth = twin.truth
    T_marker_image = inverse(T_PTIP_MARKER) @ truth.T_Ptip_I
    for label, other in routes.items():
        landing = targeting_error(twin, Calibration(result.T_ER_Ntip, other.T_EL_marker, other.image), n_targets)
        row[label] = landing.stats.mae_mm
        true_points = transform_points(T_marker_image, image_points(landing.uv_px, truth.spacing_m))
        row[TABLE3_IMAGE[label]] = ErrorStats.between(true_points, other.image.probe_points(landing.uv_px)).mae_mm
    return row, model, result


def table3(
    robot: Robot,
    seeds: Sequence[int],
    n_targets: int = 50,
    *,
    chain: bool = True,
    progress: Callable[[int], object] | None = None,
) -> Table3:
    """Table III over ``seeds`` (:func:`table3_seed` each); ``progress(1)`` after every seed."""
    rows: dict[str, list[float]] = {}
    models = []
    for seed in seeds:
        row, model = table3_seed(robot, seed, n_targets, chain)
        for label, value in row.items():
            rows.setdefault(label, []).append(value)
        if model is not None:
            models.append(model)
        if progress is not None:
            progress(1)
    return Table3.from_rows(seeds, n_targets, rows, models)


def table3_text(table: Table3) -> str:
    """Table III as text: mean ± SD over seeds, min–max, and the paper's figure beside."""
    n = len(table.seeds)
    width = max(map(len, table.maes_mm))
    seeds = f"seed {table.seeds[0]}" if n == 1 else f"{n} seeds ({table.seeds[0]}–{table.seeds[-1]})"
    lines = [
        f"TABLE III on the twin: whole-system targeting error, MAE over {table.n_targets} targets, {seeds}",
        f"  {'method':<{width}}  twin mean ± SD (mm)  min–max (mm)   paper (mm)",
    ]
    for label, maes in table.maes_mm.items():
        a = np.asarray(maes)
        refused = int(np.sum(np.isnan(a)))  # seeds whose session this method refused
        a = a[~np.isnan(a)]
        if not len(a):
            lines.append(f"  {label:<{width}}  refused on every seed{'':>20}" + TABLE3_PAPER[label])
            continue
        spread = f"{a.std(ddof=1):.3f}" if len(a) > 1 else "-"
        lines.append(
            f"  {label:<{width}}  {a.mean():6.3f} ± {spread:>5}       {a.min():.3f}–{a.max():.3f}    "
            + TABLE3_PAPER[label]
            + (f"  (refused on {refused} of {n} seeds)" if refused else "")
        )
    if table.image_mm:
        parts = []
        for label, errors in table.image_mm.items():
            a = np.asarray(errors)
            parts.append(f"{label.split(',')[0]} {a.mean():.3f}" + (f" ± {a.std(ddof=1):.3f}" if n > 1 else ""))
        lines += [
            "  Image calibration alone (the targets' pixels on the marker body vs the truth, mean ± SD, mm):",
            "    " + ", ".join(parts) + "; Shen et al. (their phantom) 1.022 ± 0.085",
        ]
    if table.chain_models:
        counts = {m: table.chain_models.count(m) for m in dict.fromkeys(table.chain_models)}
        chosen = ", ".join(f"{m} on {k} of {len(table.chain_models)}" for m, k in counts.items())
        lines.append(f"  (whole chain's image model by cross-validation: {chosen} seeds)")
    lines += [
        "  Twin: one simulated robot (geometry error, encoder noise) for every row. Phantom rows: NDI Polaris",
        "  Spectra (0.25 mm RMS, 20 frames averaged), print tolerance, landmark registration, beam thickness,",
        "  one hand-eye calibration shared. Paper: its SDA10F in the lab (Table III); Shen et al.'s figure is",
        "  their image calibration alone.",
    ]
    return "\n".join(lines)
