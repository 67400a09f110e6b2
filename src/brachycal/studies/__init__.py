"""Calibrations run on the digital twin: targeting, studies, design comparisons, the demo, example files.

- :func:`targeting_error` — the end-to-end targeting error of a calibration on the twin
  (:class:`TargetingResult`, metres in ``base_link``); :func:`tracker_route` — the N-wire and
  hand–eye route with an optical tracker on the same twin (:class:`NWireSimConfig`);
  :func:`phantom_route` — the same with a multi-wedge or arbitrary-wire phantom
  (:func:`simulate_phantom`); :func:`table3` — Table III over seeds (:class:`Table3`).
- :func:`run_demo` — ``brachycal demo`` (:class:`DemoRun`); :func:`sweep`, :func:`run_study`,
  :func:`summarise` — ``brachycal study``; :func:`compare_designs`, :func:`evaluate_design` —
  ``brachycal design`` (:data:`DESIGNS`); :func:`compare_excitation`, :func:`evaluate_excitation` —
  ``brachycal design --robot-error`` (excitation poses recorded on a twin with robot error by
  :func:`extended_twin_session`).
- :class:`StepperSetup` — a TRUS probe on a brachytherapy stepper over an N-wire phantom, as the truth
  of simulated frames (wire points, segmented frames); :data:`STEPPER_TWIN` — the set-up of the
  bundled stepper example (``examples/stepper``).

This layer sits above :mod:`brachycal.simulation` (the twin itself) and :mod:`brachycal.calibration`
and :mod:`brachycal.planning` (what it runs on the twin).
"""

from typing import TYPE_CHECKING

from brachycal._lazy import attach

if TYPE_CHECKING:  # imported on first use (each study loads the robot, SciPy and mink)
    from brachycal.studies.demo import DemoRun, Table3, run_demo, table3
    from brachycal.studies.design import DESIGNS, compare_designs, compare_excitation, evaluate_design
    from brachycal.studies.excitation import evaluate_excitation, extended_twin_session
    from brachycal.studies.nwire_twin import NWireSimConfig, TrackerRoute, tracker_route
    from brachycal.studies.phantom_twin import PhantomSession, phantom_route, simulate_phantom
    from brachycal.studies.stepper_twin import STEPPER_TWIN, StepperSetup
    from brachycal.studies.study import STUDY_METHODS, RunParams, run_study, summarise, sweep
    from brachycal.studies.targeting import TargetingResult, targeting_error

__getattr__, __dir__ = attach(__name__, __file__)

__all__ = [
    "DESIGNS",
    "STEPPER_TWIN",
    "STUDY_METHODS",
    "DemoRun",
    "NWireSimConfig",
    "PhantomSession",
    "RunParams",
    "StepperSetup",
    "Table3",
    "TargetingResult",
    "TrackerRoute",
    "compare_designs",
    "compare_excitation",
    "evaluate_design",
    "evaluate_excitation",
    "extended_twin_session",
    "phantom_route",
    "run_demo",
    "run_study",
    "simulate_phantom",
    "summarise",
    "sweep",
    "table3",
    "targeting_error",
    "tracker_route",
]
