"""Whole-chain calibration: one least-squares problem over every recorded datum.

Unknowns: the needle tip and rotation on the needle arm's flange (``T_ER_Ntip``), the probe tip on
the probe arm's flange (``T_EL_Ptip``), the image on the probe (``T_Ptip_I``), its pixel scale (per
image model, :data:`IMAGE_MODELS`) and the two reference tips; metres and radians inside.
:func:`fit_chain` solves it, :class:`ChainFit` holds the estimate and its covariance.

Design: ``docs/design/chain.md``.
"""

from __future__ import annotations

from brachycal.calibration.chain.conditioning import (
    RCOND_LIMIT,
    ROTATION_SD_LIMIT,
    Conditioning,
    check_conditioning,
)
from brachycal.calibration.chain.data import (
    AXES_MOVES,
    ChainData,
)
from brachycal.calibration.chain.fit import (
    FLAG_ROUNDS,
    NOISE_ITERATIONS,
    NOISE_SETTLED,
    CovarianceTerms,
    FinalStage,
    assemble,
    covariance_terms,
    final_stage,
    fit_chain,
    fit_problem,
    offset_joints,
    robust_stage,
    settle_noise,
)
from brachycal.calibration.chain.identifiability import (
    IDENTIFIABLE_TOLERANCE,
    identifiable_joint_offsets,
    information_blocks,
)
from brachycal.calibration.chain.image_models import (
    COMPLEXITY,
    IMAGE_MODELS,
    MODELS,
    SCANNER_SOUND_SPEED,
    ImageModel,
    image_model,
)
from brachycal.calibration.chain.jacobian import (
    chain_jacobian,
)
from brachycal.calibration.chain.layout import (
    BLOCK_LABELS,
    FIXED_BLOCKS,
    ROTATIONS,
    ParameterLayout,
)
from brachycal.calibration.chain.model_choice import (
    FOLDS_PER_RUN,
    FoldRuns,
    ModelChoice,
    ModelSelection,
    cross_validate,
    fold_errors,
    select_model,
)
from brachycal.calibration.chain.noise import (
    GROUPS,
    IMAGE_AXES,
    INITIAL_SIGMA,
    MIN_NOISE_DOF,
    POOLED_WITH,
    RESOLUTION_M,
    NoiseLevel,
    assumed_level,
    hat_factor,
    image_axis_levels,
    leverages,
    measured_level,
    noise_levels,
    noise_share,
)
from brachycal.calibration.chain.problem import (
    OFFSET_PRIOR_SD,
    OUTLIER_THRESHOLD,
    ChainProblem,
)
from brachycal.calibration.chain.residuals import (
    chain_residuals,
    finite_difference_steps,
    image_residuals,
)
from brachycal.calibration.chain.result import (
    ChainFit,
    robot_jacobian,
)
from brachycal.calibration.chain.robot_terms import (
    DEFAULT_ROBOT_ACCURACY,
    MAX_ENCODER_SD_RAD,
    MAX_ROBOT_ROTATION_SD_RAD,
    MAX_ROBOT_TRANSLATION_SD_M,
    ROBOT_STEP,
    RobotAccuracy,
    joint_twists,
    robot_jacobian_at,
)

__all__ = [
    "AXES_MOVES",
    "BLOCK_LABELS",
    "COMPLEXITY",
    "DEFAULT_ROBOT_ACCURACY",
    "FIXED_BLOCKS",
    "FLAG_ROUNDS",
    "FOLDS_PER_RUN",
    "GROUPS",
    "IDENTIFIABLE_TOLERANCE",
    "IMAGE_AXES",
    "IMAGE_MODELS",
    "INITIAL_SIGMA",
    "MAX_ENCODER_SD_RAD",
    "MAX_ROBOT_ROTATION_SD_RAD",
    "MAX_ROBOT_TRANSLATION_SD_M",
    "MIN_NOISE_DOF",
    "MODELS",
    "NOISE_ITERATIONS",
    "NOISE_SETTLED",
    "OFFSET_PRIOR_SD",
    "OUTLIER_THRESHOLD",
    "POOLED_WITH",
    "RCOND_LIMIT",
    "RESOLUTION_M",
    "ROBOT_STEP",
    "ROTATIONS",
    "ROTATION_SD_LIMIT",
    "SCANNER_SOUND_SPEED",
    "ChainData",
    "ChainFit",
    "ChainProblem",
    "Conditioning",
    "CovarianceTerms",
    "FinalStage",
    "FoldRuns",
    "ImageModel",
    "ModelChoice",
    "ModelSelection",
    "NoiseLevel",
    "ParameterLayout",
    "RobotAccuracy",
    "assemble",
    "assumed_level",
    "chain_jacobian",
    "chain_residuals",
    "check_conditioning",
    "covariance_terms",
    "cross_validate",
    "final_stage",
    "finite_difference_steps",
    "fit_chain",
    "fit_problem",
    "fold_errors",
    "hat_factor",
    "identifiable_joint_offsets",
    "image_axis_levels",
    "image_model",
    "image_residuals",
    "information_blocks",
    "joint_twists",
    "leverages",
    "measured_level",
    "noise_levels",
    "noise_share",
    "offset_joints",
    "robot_jacobian",
    "robot_jacobian_at",
    "robust_stage",
    "select_model",
    "settle_noise",
]
