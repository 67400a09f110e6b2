"""Simulated sessions with known truth: exact sessions, the digital twin, and how to judge them.

- :func:`exact_session` — a noise-free session hiding a :class:`SessionTruth` (from
  :func:`default_truth`): a calibration of it must return the truth to numerical precision.
- :func:`simulate` — the digital twin (:class:`TwinConfig`: robot geometry error, encoder, jog,
  annotation, speed of sound, beam thickness, outliers; each with a switch and its own seeded
  stream) as a :class:`Twin`; :func:`write_twin` / :func:`read_twin` store it (:data:`TWIN_FILES`).
- :func:`record` — the twin's session as a lab records it (:class:`Recording`: a 100 Hz joint log
  with moves between the stops, marks, frames, the plan); :func:`write_recording` writes it
  (:data:`RECORDING_FILES`, optionally a ROS 2 bag and B-mode frames) for ``brachycal session build``.
- :func:`render_frame` — a B-mode-like frame of the needle (:class:`BModeSettings`: speckle, shaft,
  tip, beam thickness, shadow, attenuation, TGC, noise, log compression, sector; each switchable
  and seeded); :func:`render_samples` the twin's sample frames, :func:`true_tip_px` their true tips.
- :func:`simulate_touches` / :func:`simulate_tracker` — any arm off its URDF (:func:`arm_errors`)
  touching fixed points from many postures (:class:`TouchRecording`, written as place folders by
  :func:`write_touch_places`) or seen by a tracker (:class:`TrackerRecording`, a table and its
  column spec: :func:`write_tracker_table`, :func:`tracker_columns_text`), for ``brachycal robot identify``.

What runs calibrations on the twin (targeting, studies, designs, the demo) is :mod:`brachycal.studies`.
"""

from typing import TYPE_CHECKING, Any

from brachycal._lazy import attach

if TYPE_CHECKING:  # imported on first use (each simulation loads the robot, SciPy and mink)
    from brachycal.simulation.arm_touches import (
        TouchRecording,
        TrackerRecording,
        arm_errors,
        simulate_touches,
        simulate_tracker,
        touch_postures,
        tracker_columns_text,
        write_touch_places,
        write_touch_table,
        write_tracker_table,
    )
    from brachycal.simulation.bmode import BModeSettings, NeedleView, render_frame, render_samples, true_tip_px
    from brachycal.simulation.exact import SessionTruth, default_truth, exact_session
    from brachycal.simulation.recording import RECORDING_FILES, Recording, RecordingConfig, record, write_recording
    from brachycal.simulation.twin import Twin, TwinConfig, simulate
    from brachycal.simulation.twin_files import TWIN_FILES, read_twin, write_twin

_lazy_getattr, __dir__ = attach(__name__, __file__)

#: Names that moved to :mod:`brachycal.studies` (the studies sit above the twin, and this package
#: may not import them): asking for one here says where it went.
_MOVED_TO_STUDIES = (
    "DESIGNS DemoRun NWireSimConfig PhantomSession RunParams STUDY_METHODS Table3 TargetingResult TrackerRoute "
    "compare_designs compare_excitation evaluate_design evaluate_excitation extended_twin_session phantom_route "
    "run_demo run_study simulate_phantom summarise sweep table3 targeting_error tracker_route"
).split()


def __getattr__(name: str) -> Any:
    if name in _MOVED_TO_STUDIES:
        # ImportError, not AttributeError: ``from brachycal.simulation import x`` keeps this message.
        raise ImportError(f"brachycal.simulation.{name} moved: use brachycal.studies.{name}", name=name)
    return _lazy_getattr(name)


__all__ = [
    "RECORDING_FILES",
    "TWIN_FILES",
    "BModeSettings",
    "NeedleView",
    "Recording",
    "RecordingConfig",
    "SessionTruth",
    "TouchRecording",
    "TrackerRecording",
    "Twin",
    "TwinConfig",
    "arm_errors",
    "default_truth",
    "exact_session",
    "read_twin",
    "record",
    "render_frame",
    "render_samples",
    "simulate",
    "simulate_touches",
    "simulate_tracker",
    "touch_postures",
    "tracker_columns_text",
    "true_tip_px",
    "write_recording",
    "write_touch_places",
    "write_touch_table",
    "write_tracker_table",
    "write_twin",
]
