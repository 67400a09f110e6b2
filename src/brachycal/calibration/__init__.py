"""Calibration: the estimators, pure functions on arrays and small dataclasses (SI units inside).

``T_a_b`` maps frame b into frame a; lengths in metres. The paper's sequential method
(:func:`calibrate`, :func:`locate`, :class:`ImageCalibration`) and what goes beyond it: the whole
chain, phantoms, robot identification, result files, temporal calibration. Overview:
``docs/api/calibration.md``.
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
    from brachycal.calibration.phantom.features import PhantomCalibration
    from brachycal.calibration.phantom.hand_eye import hand_eye
    from brachycal.calibration.phantom.nwire import NWireCalibration, calibrate_nwire, wire_point_pairs
    from brachycal.calibration.phantom.nwire_file import (
        NWireRun,
        StoredNWire,
        nwire_from_files,
        read_nwire,
        write_nwire,
    )
    from brachycal.calibration.phantom.phantom_file import PhantomObservations
    from brachycal.calibration.phantom.phantom_file import read_observations as read_phantom_observations
    from brachycal.calibration.phantom.phantom_file import write_observations as write_phantom_observations
    from brachycal.calibration.phantom.pivot import PivotResult, pivot_algebraic, pivot_robust
    from brachycal.calibration.phantom.pivot_file import (
        PIVOT_METHODS,
        PivotCalibration,
        StoredPivot,
        pivot_from_file,
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
    from brachycal.calibration.result import ImageCalibration, PredictedUncertainty
    from brachycal.calibration.robot.identification import (
        RobotIdentification,
        corrected_robot,
        cross_validate_identification,
        identify_robot,
    )
    from brachycal.calibration.robot.observability import Criterion, Observation, base_criterion, observation_rows
    from brachycal.calibration.sequential.method import (
        CalibrationResult,
        ToolCalibration,
        calibrate,
        locate,
        loo_points,
    )
    from brachycal.calibration.session.calibrate import SessionCalibration, calibrate_folder
    from brachycal.calibration.session.chain_report import ChainReport, calibrate_chain
    from brachycal.calibration.session.result_file import RobotRecord, StoredCalibration, read_result, write_result
    from brachycal.calibration.session.result_schema import validate_result_document
    from brachycal.calibration.temporal import (
        LagEstimate,
        TemporalCalibration,
        estimate_lag,
        lag_from_plus_files,
        lag_from_signals,
        principal_motion,
    )
    from brachycal.calibration.verify.folder import FolderCheck, verify_folder

__getattr__, __dir__ = attach(__name__, __file__)

__all__ = [
    "ALL_LABELS",
    "METHODS",
    "METHOD_LABELS",
    "MODELS",
    "PAPER_METHODS",
    "PIVOT_METHODS",
    "CalibrationResult",
    "ChainFit",
    "ChainReport",
    "Criterion",
    "ErrorStats",
    "FolderCheck",
    "ImageCalibration",
    "LagEstimate",
    "NWireCalibration",
    "NWireRun",
    "Observation",
    "PhantomCalibration",
    "PhantomObservations",
    "PivotCalibration",
    "PivotResult",
    "PredictedUncertainty",
    "RobotIdentification",
    "RobotRecord",
    "SessionCalibration",
    "StoredCalibration",
    "StoredNWire",
    "StoredPivot",
    "TemporalCalibration",
    "ToolCalibration",
    "WedgePhantom",
    "WirePhantom",
    "base_criterion",
    "calibrate",
    "calibrate_chain",
    "calibrate_folder",
    "calibrate_nwire",
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
    "nwire_from_files",
    "observation_rows",
    "pivot_algebraic",
    "pivot_from_file",
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
    "verify_folder",
    "wire_point_pairs",
    "write_nwire",
    "write_phantom_observations",
    "write_pivot",
    "write_result",
]
