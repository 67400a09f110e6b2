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
    from brachycal.calibration.phantom.features import PhantomResult
    from brachycal.calibration.phantom.hand_eye import hand_eye
    from brachycal.calibration.phantom.nwire import NWireResult, calibrate_nwire, wire_point_pairs
    from brachycal.calibration.phantom.nwire_file import (
        NWireFile,
        NWireFileResult,
        calibrate_nwire_files,
        calibrate_nwire_frames,
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
    from brachycal.calibration.phantom.stepper import (
        StepperFit,
        centre_of_rotation,
        pixel_spacing,
        rotation_axis,
        rotation_encoder,
        translation_axis,
    )
    from brachycal.calibration.phantom.stepper_file import StepperFileResult, calibrate_stepper_files, write_stepper
    from brachycal.calibration.phantom.stepper_probe import (
        HoleInImage,
        PhantomRegistration,
        StepperImageFile,
        StepperImageResult,
        calibrate_stepper_image_files,
        corrected_frames,
        hole_in_image,
        read_stepper_image,
        register_phantom,
        stepper_pose,
        write_stepper_image,
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
    from brachycal.calibration.robot.arm_fit import (
        ArmFit,
        ParameterSelection,
        corrected_robot,
        fit_arm,
        flange_points,
        gravity_moments,
    )
    from brachycal.calibration.robot.evidence import EvidenceChoice
    from brachycal.calibration.robot.identification import (
        IdentificationResult,
        cross_validate_identification,
        identify_robot,
    )
    from brachycal.calibration.robot.observability import Criterion, Observation, base_criterion, observation_rows
    from brachycal.calibration.robot.touches import (
        EvidencePrior,
        TouchPlace,
        TouchReport,
        TouchResult,
        evidence_prior,
        identify_touch_folders,
        identify_touches,
        read_places,
        touch_scatter,
    )
    from brachycal.calibration.robot.tracker import (
        TrackerData,
        TrackerFit,
        TrackerIdentification,
        fit_tracker,
        identify_from_tracker,
        identify_tracker_file,
        tracker_data,
        tracker_evidence_prior,
    )
    from brachycal.calibration.robot_accuracy import RobotAccuracy
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
    from brachycal.calibration.verify.folder import FolderCheck, verify_folder

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
    "ArmFit",
    "Calibration",
    "ChainFit",
    "ChainResult",
    "Criterion",
    "ErrorStats",
    "EvidenceChoice",
    "EvidencePrior",
    "FolderCheck",
    "HoleInImage",
    "IdentificationResult",
    "ImageCalibration",
    "LagEstimate",
    "NWireFile",
    "NWireFileResult",
    "NWireResult",
    "Observation",
    "ParameterSelection",
    "PhantomObservations",
    "PhantomRegistration",
    "PhantomResult",
    "PivotFile",
    "PivotFileResult",
    "PivotResult",
    "PredictedUncertainty",
    "Provenance",
    "ResultFile",
    "RobotAccuracy",
    "RobotRecord",
    "SequentialResult",
    "SessionResult",
    "StepperFileResult",
    "StepperFit",
    "StepperImageFile",
    "StepperImageResult",
    "TemporalResult",
    "ToolCalibration",
    "TouchPlace",
    "TouchReport",
    "TouchResult",
    "TrackerData",
    "TrackerFit",
    "TrackerIdentification",
    "WedgePhantom",
    "WirePhantom",
    "base_criterion",
    "calibrate",
    "calibrate_chain",
    "calibrate_folder",
    "calibrate_nwire",
    "calibrate_nwire_files",
    "calibrate_nwire_frames",
    "calibrate_pivot_files",
    "calibrate_stepper_files",
    "calibrate_stepper_image_files",
    "calibrate_wedge",
    "calibrate_wedge_files",
    "calibrate_wire",
    "calibrate_wire_files",
    "centre_of_rotation",
    "corrected_frames",
    "corrected_robot",
    "cross_validate_identification",
    "estimate_lag",
    "evidence_prior",
    "fit_arm",
    "fit_chain",
    "fit_tracker",
    "flange_points",
    "gravity_moments",
    "hand_eye",
    "hole_in_image",
    "identify_from_tracker",
    "identify_robot",
    "identify_touch_folders",
    "identify_touches",
    "identify_tracker_file",
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
    "pixel_spacing",
    "predicted_rms_mm",
    "principal_motion",
    "read_nwire",
    "read_phantom_observations",
    "read_pivot",
    "read_places",
    "read_result",
    "read_stepper_image",
    "read_wedge_phantom",
    "read_wire_phantom",
    "register_phantom",
    "rotation_axis",
    "rotation_encoder",
    "select_model",
    "stepper_pose",
    "touch_scatter",
    "tracker_data",
    "tracker_evidence_prior",
    "translation_axis",
    "validate_result_document",
    "verify_folder",
    "wire_point_pairs",
    "write_nwire",
    "write_phantom_observations",
    "write_pivot",
    "write_result",
    "write_stepper",
    "write_stepper_image",
]
