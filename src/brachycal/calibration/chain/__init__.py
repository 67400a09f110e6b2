"""Whole-chain calibration: one least-squares problem over every recorded datum.

Unknowns ``θ``: the needle tip and needle rotation on the right flange (``T_ER_Ntip``), the probe
tip frame on the left flange (``T_EL_Ptip``), the image on the probe (``T_Ptip_I``), the image's
pixel scale (per the image model), and the two reference tips (nuisance). Residuals, each
divided by its group's noise level (metres per coordinate):

- touches: ``T_R_ER @ p_ER_Mtip``, ``T_R_ER @ p_ER_Ntip`` and ``T_R_EL @ p_EL_Ptip`` against the
  reference tip they touched (3 per touch);
- axes: the tip's move p1→p2 (p1→p3) must run along the tool's y (z) axis: its components along
  the tool's other two axes (2 per move; the move's length is not recorded, so not used);
- image samples: the needle tip through the needle arm (the SDA10F's right; ``robot.rig``) against
  the annotated pixel through the probe arm,
  ``T_R_ER p_ER_Ntip − T_R_EL T_EL_Ptip T_Ptip_I (u s_u, v s_v, 0)`` (3 per image).

Image models (one table, :data:`IMAGE_MODELS`): ``rigid`` (the scanner's spacing), ``similarity``
(one scale), ``scaled_uv`` (a scale per axis) and ``sound_speed`` (the physical model: lateral
spacing as the scanner says, depth spacing times c / 1540 m/s, with the speed of sound c estimated).
The unknowns sit in the parameter vector by name (:class:`ParameterLayout`, ``ChainFit.block``).

Two stages, both least-squares solves (:mod:`~brachycal.calibration.least_squares`: SciPy's trust-region
objective and tolerances, without its per-call overhead) from the sequential result:

1. **Robust stage** (finds gross errors): soft-L1 loss on the normalised residuals, each group's
   noise level re-estimated from its residuals by the median absolute deviation (× 1.4826, with
   the degrees-of-freedom correction below). Image samples whose 3D residual exceeds
   :data:`OUTLIER_THRESHOLD` × √3 σ_image are flagged: for Gaussian noise ``|r|²/σ²`` is χ²₃, and
   3 × 3.5² = 36.75 puts a clean sample past it with probability 5e-8 (3e-6 per session of 64),
   while a 15 px annotation mistake (2.9 mm) sits at about 8 × √3 σ_image.
2. **Final stage** (the estimate and its covariance): the flagged samples are left out and the
   problem is solved by plain least squares (the efficient estimator for the remaining,
   Gaussian-like noise; the soft-L1 estimate's variance is E[ψ²]/E[ψ']² = 1.08 times that, while
   its Gauss–Newton covariance, ``(E[ψ'] JᵀJ)⁻¹`` with E[ψ'] = 0.56, states 1.77 times: SDs 1.28×
   too wide, as the speed of sound's were). Each group's noise level is its residual sum
   of squares over its residual degrees of freedom ``n_g − Σ_{i∈g} h_ii`` (``h`` the leverages
   of the weighted problem: the unbiased estimate for a linear model), iterated with the weights.
   The covariance is ``(JᵀJ)⁻¹`` of the Jacobian of the normalised residuals. A group with fewer
   than :data:`MIN_NOISE_DOF` residual degrees of freedom cannot estimate its own noise (its
   relative error would exceed 25 %): the axes moves (8 residuals, 6 rotations: 2 degrees of
   freedom) take the touches' level (the same robot placing the same tools), reported as assumed.
   A group whose residuals are below :data:`RESOLUTION_M` is reported as below resolution.

Conditioning (refusals with :class:`~brachycal.errors.DegenerateDataError`): see
:func:`check_conditioning`.

Identifiability: the image samples fix only the product ``T_EL_Ptip @ T_Ptip_I`` (the probe-tip
frame is a convention); the probe touches fix ``p_EL_Ptip``, the axes moves ``R_EL_Ptip``. The
needle rotation is fixed by its axes moves alone.

Robot corrections (optional, ``joint_offsets=True``): zero offsets of the joints that this
session can tell apart from the other unknowns. :func:`identifiable_joint_offsets` measures, per
joint, how much of the residuals' response to its offset lies outside the span of the chain
parameters. Two are never identifiable here: the shared joints (``robot.rig.shared_joints``, the
SDA10F's torso: they turn both arms together, so the data only see them through the reference
tips, which are unknown too; a robot of two separate arms has none) and each arm's last joint
(its offset is a turn about the flange axis, which the tool transforms absorb). The others are
estimated with a weak prior (0.01° SD) that keeps poorly excited ones near zero.

The robot model's own error (consider covariance, :class:`RobotAccuracy`): the physical robot's
joint origins differ from the URDF's. Where the session's data see it (the spread of touches
across poses, of images across the cube) it is in the noise levels; where they cannot (e.g. an
offset of the left arm against the right one, which the probe-tip touches cannot tell from the
probe tip) it shifts the estimate without any trace in the residuals. With a stated accuracy —
each joint's origin off by a small motion ``c_j`` (translation ``v``, rotation ``ω`` about the
origin's own axes, plus a zero offset about the joint axis: the model
:func:`brachycal.simulation.twin.physical_kinematics` draws from), ``Σ_c`` its covariance — the
estimate's sensitivity is ``S = (JᵀJ)⁻¹ Jᵀ J_c`` (``J_c`` the normalised residuals' Jacobian with
respect to the 6 components of every ``c_j``, :func:`robot_jacobian`) and the stated covariance
``(JᵀJ)⁻¹ + S Σ_c Sᵀ``. (Sign: ``c`` is the physical robot's deviation from the model; at the true
parameters the model's residuals are ``−J_c c``, so the estimate moves by ``+(JᵀJ)⁻¹Jᵀ J_c c``;
the sign matters for the landing error, where this shift and ``c``'s direct effect partly cancel.)
``benchmarks/chain_checks.py`` measures the coverage on the twin.

Modules (one concept each): ``image_models`` (the table), ``layout`` (the parameter vector),
``data`` (:class:`ChainData`), ``residuals`` and ``jacobian`` (the problem's functions),
``robot_terms`` (:class:`RobotAccuracy`, :func:`joint_twists`, :func:`robot_jacobian`), ``noise``,
``conditioning``, ``solver`` (the small dense least-squares solver every stage uses), ``problem``
(:class:`ChainProblem`: one solve), ``fit`` (:func:`fit_chain`'s
stages), ``result`` (:class:`ChainFit`), ``model_choice`` (:func:`select_model`, :func:`cross_validate`)
and ``identifiability``.

Cross-validation's refits are independent of one another: model choice (each model's K folds, the
most flexible model's fit) and leave-one-out (runs of at most :data:`FOLDS_PER_RUN` warm-started
folds) share the cores (:func:`brachycal.calibration.parallel.parallel_calls`), with the same figures
on any number of cores.
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
    RESOLUTION_M,
    NoiseLevel,
    hat_factor,
    image_axis_levels,
    leverages,
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
    "noise_levels",
    "noise_share",
    "offset_joints",
    "robot_jacobian",
    "robot_jacobian_at",
    "robust_stage",
    "select_model",
    "settle_noise",
]
