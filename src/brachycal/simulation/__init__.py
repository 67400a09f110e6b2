"""Simulated sessions with known truth: exact sessions, the digital twin, and how to judge them.

- :func:`exact_session` — a noise-free session hiding a :class:`SessionTruth` (from
  :func:`default_truth`): a calibration of it must return the truth to numerical precision.
- :func:`simulate` — the digital twin (:class:`TwinConfig`: robot geometry error, encoder, jog,
  annotation, speed of sound, beam thickness, outliers; each with a switch and its own seeded
  stream) as a :class:`Twin`; :func:`write_twin` / :func:`read_twin` store it (:data:`TWIN_FILES`).
- :func:`targeting_error` — the end-to-end targeting error of a calibration on the twin
  (:class:`TargetingResult`, metres in ``base_link``); :func:`tracker_route` — the N-wire and
  hand–eye route with an optical tracker on the same twin (:class:`NWireSimConfig`);
  :func:`phantom_route` — the same with a multi-wedge or arbitrary-wire phantom
  (:func:`simulate_phantom`); :func:`table3` — Table III over seeds (:class:`Table3`).
- :func:`record` — the twin's session as a lab records it (:class:`Recording`: a 100 Hz joint log
  with moves between the stops, marks, frames, the plan); :func:`write_recording` writes it
  (:data:`RECORDING_FILES`, optionally a ROS 2 bag and B-mode frames) for ``brachycal session build``.
- :func:`render_frame` — a B-mode-like frame of the needle (:class:`BModeSettings`: speckle, shaft,
  tip, beam thickness, shadow, attenuation, TGC, noise, log compression, sector; each switchable
  and seeded); :func:`render_samples` the twin's sample frames, :func:`true_tip_px` their true tips.
- :func:`run_demo` — ``brachycal demo`` (:class:`DemoRun`); :func:`sweep`, :func:`run_study`,
  :func:`summarise` — ``brachycal study``; :func:`compare_designs`, :func:`evaluate_design` —
  ``brachycal design`` (:data:`DESIGNS`); :func:`compare_excitation`, :func:`evaluate_excitation` —
  ``brachycal design --robot-error`` (excitation poses recorded on a twin with robot error by
  :func:`extended_twin_session`).
"""

from typing import TYPE_CHECKING

from brachycal._lazy import attach

if TYPE_CHECKING:  # imported on first use (each simulation loads the robot, SciPy and mink)
    from brachycal.simulation.bmode import BModeSettings, NeedleView, render_frame, render_samples, true_tip_px
    from brachycal.simulation.demo import DemoRun, Table3, run_demo, table3
    from brachycal.simulation.design import DESIGNS, compare_designs, compare_excitation, evaluate_design
    from brachycal.simulation.exact import SessionTruth, default_truth, exact_session
    from brachycal.simulation.excitation_twin import evaluate_excitation, extended_twin_session
    from brachycal.simulation.nwire_twin import NWireSimConfig, TrackerRoute, tracker_route
    from brachycal.simulation.phantom_twin import PhantomSession, phantom_route, simulate_phantom
    from brachycal.simulation.recording import RECORDING_FILES, Recording, RecordingConfig, record, write_recording
    from brachycal.simulation.study import STUDY_METHODS, RunParams, run_study, summarise, sweep
    from brachycal.simulation.targeting import TargetingResult, targeting_error
    from brachycal.simulation.twin import Twin, TwinConfig, simulate
    from brachycal.simulation.twin_files import TWIN_FILES, read_twin, write_twin

__getattr__, __dir__ = attach(__name__, __file__)

__all__ = [
    "DESIGNS",
    "RECORDING_FILES",
    "STUDY_METHODS",
    "TWIN_FILES",
    "BModeSettings",
    "DemoRun",
    "NWireSimConfig",
    "NeedleView",
    "PhantomSession",
    "Recording",
    "RecordingConfig",
    "RunParams",
    "SessionTruth",
    "Table3",
    "TargetingResult",
    "TrackerRoute",
    "Twin",
    "TwinConfig",
    "compare_designs",
    "compare_excitation",
    "default_truth",
    "evaluate_design",
    "evaluate_excitation",
    "exact_session",
    "extended_twin_session",
    "phantom_route",
    "read_twin",
    "record",
    "render_frame",
    "render_samples",
    "run_demo",
    "run_study",
    "simulate",
    "simulate_phantom",
    "summarise",
    "sweep",
    "table3",
    "targeting_error",
    "tracker_route",
    "true_tip_px",
    "write_recording",
    "write_twin",
]
