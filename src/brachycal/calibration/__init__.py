"""Calibration: the estimators, pure functions on arrays and small dataclasses (SI units inside).

The paper's sequential method, step by step (``T_a_b`` maps frame b into frame a; metres):

- :func:`calibrate` — a whole session: reference tips, ``T_ER_Ntip`` (needle tip on the needle
  arm's flange ER: the SDA10F's right ``tool0``, ``robot.rig.needle_flange`` on any robot),
  ``T_EL_Ptip`` (probe tip on the probe arm's flange EL) with Table I, and ``T_Ptip_I`` (image on
  the probe) by every method of :data:`METHODS` with its leave-one-out figures (Table II), as a
  :class:`CalibrationResult`; :func:`calibrate_folder` reads a session folder first (and can add
  the whole chain); :func:`loo_points` gives one method's leave-one-out points (Fig. 10);
  :func:`locate` maps image pixels to the robot's base frame through a calibration (targeting).
- :class:`ImageCalibration` — a rigid ``T_Ptip_I (4, 4)`` with the pixel spacing ``(2,)`` it goes
  with, metres per pixel; :class:`ErrorStats` — MAE, RMSE, SD and max of 3D errors (``*_mm``).

Beyond the paper: the whole chain as one least-squares problem (:func:`calibrate_chain`,
:func:`fit_chain`, :func:`select_model`; its uncertainty with :func:`landing_covariance` and
:func:`predicted_rms_mm`); pivot calibration (:func:`pivot_algebraic`, :func:`pivot_robust`, and
of a pose-list file :func:`pivot_from_file`); N-wire phantom calibration from PLUS files
(:func:`nwire_from_files`); the multi-wedge and arbitrary-wire phantoms (:func:`read_wedge_phantom`,
:func:`calibrate_wedge`, :func:`image_pose_in_phantom`, :func:`read_wire_phantom`, :func:`calibrate_wire`,
:func:`read_phantom_observations`: a :class:`PhantomCalibration`); hand–eye calibration (:func:`hand_eye`);
the robot's own geometry
identified with the chain (:func:`identify_robot`, :class:`RobotIdentification`,
:func:`corrected_robot`, :func:`cross_validate_identification`) and which extra observations would
identify it best (:func:`base_criterion`, :func:`observation_rows`: the A-optimal criterion on the
landing error, :class:`Criterion`; an :class:`Observation` is a touch or an image sample). Result files:
``brachycal-result/1`` (:func:`write_result`, :func:`read_result`; :class:`RobotRecord` says which
robot a result was calibrated with; :func:`validate_result_document` checks a whole document's
types, shapes, finite numbers, ranges and proper rotations before it is used), ``brachycal-pivot/1``
(:func:`write_pivot`, :func:`read_pivot`), ``brachycal-nwire/1`` (:func:`write_nwire`,
:func:`read_nwire`). Temporal calibration: the lag between two time-stamped position signals
(:func:`estimate_lag`, a :class:`LagEstimate`), from PLUS's water-tank recordings
(:func:`lag_from_plus_files`) or any video and pose stream (:func:`lag_from_signals`).
"""

from typing import TYPE_CHECKING

from brachycal._lazy import attach

if TYPE_CHECKING:  # imported on first use: an option's choices (METHODS) need not load SciPy's optimisers
    from brachycal.calibration.chain import MODELS, ChainFit, fit_chain, select_model
    from brachycal.calibration.chain.uncertainty import (
        inside_ellipsoid,
        landing_covariance,
        landing_jacobian,
        predicted_rms_mm,
    )
    from brachycal.calibration.labels import ALL_LABELS, METHOD_LABELS, METHODS, PAPER_METHODS
    from brachycal.calibration.metrics import ErrorStats
    from brachycal.calibration.phantom.features import PhantomResult
    from brachycal.calibration.phantom.hand_eye import hand_eye
    from brachycal.calibration.phantom.nwire import NWireResult, calibrate_nwire, wire_point_pairs
    from brachycal.calibration.phantom.nwire_file import (
        NWireFile,
        NWireFileResult,
        calibrate_nwire_files,
        read_nwire,
        write_nwire,
    )
    from brachycal.calibration.phantom.phantom_file import PhantomObservations
    from brachycal.calibration.phantom.phantom_file import read_observations as read_phantom_observations
    from brachycal.calibration.phantom.phantom_file import write_observations as write_phantom_observations
    from brachycal.calibration.phantom.pivot import PivotResult, pivot_algebraic, pivot_robust
    from brachycal.calibration.phantom.pivot_file import (
        PIVOT_METHODS,
        PivotFile,
        PivotFileResult,
        calibrate_pivot_files,
        read_pivot,
        write_pivot,
    )
    from brachycal.calibration.phantom.wedge import (
        WedgePhantom,
        calibrate_wedge,
        calibrate_wedge_files,
        image_pose_in_phantom,
        read_wedge_phantom,
    )
    from brachycal.calibration.phantom.wire import WirePhantom, calibrate_wire, calibrate_wire_files, read_wire_phantom
    from brachycal.calibration.result import Calibration, ImageCalibration, PredictedUncertainty, Provenance
    from brachycal.calibration.robot.identification import (
        IdentificationResult,
        corrected_robot,
        cross_validate_identification,
        identify_robot,
    )
    from brachycal.calibration.robot.observability import Criterion, Observation, base_criterion, observation_rows
    from brachycal.calibration.sequential.method import (
        SequentialResult,
        ToolCalibration,
        calibrate,
        locate,
        loo_points,
    )
    from brachycal.calibration.session.calibrate import SessionResult, calibrate_folder
    from brachycal.calibration.session.chain_report import ChainResult, calibrate_chain
    from brachycal.calibration.session.result_file import ResultFile, RobotRecord, read_result, write_result
    from brachycal.calibration.session.result_schema import validate_result_document
    from brachycal.calibration.temporal import (
        LagEstimate,
        TemporalResult,
        estimate_lag,
        lag_from_plus_files,
        lag_from_signals,
        principal_motion,
    )

#: Former names of results and file entry points, given for one release with a DeprecationWarning.
_RENAMED = {
    "CalibrationResult": "SequentialResult",
    "ChainReport": "ChainResult",
    "PivotCalibration": "PivotFileResult",
    "StoredPivot": "PivotFile",
    "pivot_from_file": "calibrate_pivot_files",
    "NWireCalibration": "NWireResult",
    "NWireRun": "NWireFileResult",
    "StoredNWire": "NWireFile",
    "nwire_from_files": "calibrate_nwire_files",
    "PhantomCalibration": "PhantomResult",
    "TemporalCalibration": "TemporalResult",
    "SessionCalibration": "SessionResult",
    "RobotIdentification": "IdentificationResult",
    "StoredCalibration": "ResultFile",
}

__getattr__, __dir__ = attach(__name__, __file__, deprecated=_RENAMED)

__all__ = [
    "ALL_LABELS",
    "METHODS",
    "METHOD_LABELS",
    "MODELS",
    "PAPER_METHODS",
    "PIVOT_METHODS",
    "Calibration",
    "ChainFit",
    "ChainResult",
    "Criterion",
    "ErrorStats",
    "IdentificationResult",
    "ImageCalibration",
    "LagEstimate",
    "NWireFile",
    "NWireFileResult",
    "NWireResult",
    "Observation",
    "PhantomObservations",
    "PhantomResult",
    "PivotFile",
    "PivotFileResult",
    "PivotResult",
    "PredictedUncertainty",
    "Provenance",
    "ResultFile",
    "RobotRecord",
    "SequentialResult",
    "SessionResult",
    "TemporalResult",
    "ToolCalibration",
    "WedgePhantom",
    "WirePhantom",
    "base_criterion",
    "calibrate",
    "calibrate_chain",
    "calibrate_folder",
    "calibrate_nwire",
    "calibrate_nwire_files",
    "calibrate_pivot_files",
    "calibrate_wedge",
    "calibrate_wedge_files",
    "calibrate_wire",
    "calibrate_wire_files",
    "corrected_robot",
    "cross_validate_identification",
    "estimate_lag",
    "fit_chain",
    "hand_eye",
    "identify_robot",
    "image_pose_in_phantom",
    "inside_ellipsoid",
    "lag_from_plus_files",
    "lag_from_signals",
    "landing_covariance",
    "landing_jacobian",
    "locate",
    "loo_points",
    "observation_rows",
    "pivot_algebraic",
    "pivot_robust",
    "predicted_rms_mm",
    "principal_motion",
    "read_nwire",
    "read_phantom_observations",
    "read_pivot",
    "read_result",
    "read_wedge_phantom",
    "read_wire_phantom",
    "select_model",
    "validate_result_document",
    "wire_point_pairs",
    "write_nwire",
    "write_phantom_observations",
    "write_pivot",
    "write_result",
]
