"""The chain's parameter vector: named blocks, the one place that knows their indices.

``x`` holds, in order, the fixed blocks of :data:`FIXED_BLOCKS` (tool tips and origins in metres,
rotations as rotation vectors in radians about starting rotations ``base``), then the image
model's scale factors (``scale``, :mod:`~brachycal.calibration.chain.image_models`), then the
estimated joint zero offsets (``joint_offsets``, radians). Everything else reads ``x`` through
:meth:`ParameterLayout.blocks`, :meth:`ParameterLayout.unpack` or ``ChainFit.block``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from brachycal.calibration.chain.image_models import ImageModel, image_model
from brachycal.calibration.sequential.method import SequentialResult
from brachycal.se3 import FloatArray, rotation

#: The fixed blocks of the parameter vector, in order: name → length.
FIXED_BLOCKS = {
    "p_ER_Ntip": 3,
    "rot_ER_Ntip": 3,
    "rot_EL_Ptip": 3,
    "p_EL_Ptip": 3,
    "rot_Ptip_I": 3,
    "p_Ptip_I": 3,
    "p_R_Rtip1": 3,
    "p_R_Rtip2": 3,
}
N_FIXED = sum(FIXED_BLOCKS.values())
#: What each block is, and the session file whose data determine it (for refusals).
BLOCK_LABELS = {
    "p_ER_Ntip": ("the needle tip", "touches.csv"),
    "rot_ER_Ntip": ("the needle rotation", "axes.csv"),
    "rot_EL_Ptip": ("the probe rotation", "axes.csv"),
    "p_EL_Ptip": ("the probe tip", "touches.csv"),
    "rot_Ptip_I": ("the image rotation", "samples.csv"),
    "p_Ptip_I": ("the image origin", "samples.csv"),
    "p_R_Rtip1": ("reference tip rtip1", "touches.csv"),
    "p_R_Rtip2": ("reference tip rtip2", "touches.csv"),
    "scale": ("the pixel scale", "samples.csv"),
    "joint_offsets": ("the joint offsets", "samples.csv"),
}
#: The rotation blocks (rotation vectors about the starting rotations of ``base``).
ROTATIONS = ("rot_ER_Ntip", "rot_EL_Ptip", "rot_Ptip_I")
#: Starting rotation in ``base`` of each rotation block.
BASE_ROTATIONS = {"rot_ER_Ntip": "R_ER_Ntip", "rot_EL_Ptip": "R_EL_Ptip", "rot_Ptip_I": "R_Ptip_I"}

#: ``(T_ER_Ntip, T_EL_Ptip, T_Ptip_I, p_R_Rtip (2, 3), spacing_m (2,))``.
Unpacked = tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]


@dataclass(frozen=True)
class ParameterLayout:
    """Where each unknown sits in ``x`` for an image model and a set of estimated joint offsets.

    Attributes:
        model: the image model's name (:data:`~brachycal.calibration.chain.image_models.IMAGE_MODELS`).
        offset_joints: indices (``robot.joint_names`` order) of the joints whose zero offsets are estimated.

    Raises:
        InputError: an unknown image model.
    """

    model: str
    offset_joints: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        image_model(self.model)

    @property
    def image(self) -> ImageModel:
        """The image model."""
        return image_model(self.model)

    @property
    def n_scale(self) -> int:
        return self.image.n_scale

    @property
    def size(self) -> int:
        """``P``, the length of ``x``."""
        return N_FIXED + self.n_scale + len(self.offset_joints)

    def blocks(self) -> dict[str, slice]:
        """Parameter name → its slice of the parameter vector (the one place that knows the layout)."""
        return dict(self._blocks)

    @cached_property
    def _blocks(self) -> dict[str, slice]:
        # Computed once per layout: the residuals and Jacobian look the blocks up at every evaluation.
        out = {}
        start = 0
        for name, n in FIXED_BLOCKS.items():
            out[name] = slice(start, start + n)
            start += n
        out["scale"] = slice(N_FIXED, N_FIXED + self.n_scale)
        out["joint_offsets"] = slice(N_FIXED + self.n_scale, self.size)
        return out

    def offsets(self, x: FloatArray, nq: int) -> FloatArray:
        """``(nq,)`` joint zero offsets (radians) of ``x``: zero for joints not estimated."""
        out = np.zeros(nq)
        out[list(self.offset_joints)] = x[self.blocks()["joint_offsets"]]
        return out

    def unpack(self, x: FloatArray, base: dict[str, FloatArray], nominal_spacing: FloatArray) -> Unpacked:
        """The chain at ``x``: ``T_ER_Ntip``, ``T_EL_Ptip``, ``T_Ptip_I`` ``(4, 4)``, the reference tips
        ``(2, 3)`` in ``base_link`` and the pixel spacing ``(2,)`` (metres; ``base`` the starting rotations)."""
        b = self._blocks

        def transform(rot: str, origin: str) -> FloatArray:
            T = np.eye(4)
            T[:3, :3] = rotation(x[b[rot]]) @ base[BASE_ROTATIONS[rot]]
            T[:3, 3] = x[b[origin]]
            return T

        T_ER_Ntip = transform("rot_ER_Ntip", "p_ER_Ntip")
        T_EL_Ptip = transform("rot_EL_Ptip", "p_EL_Ptip")
        T_Ptip_I = transform("rot_Ptip_I", "p_Ptip_I")
        rtips = x[b["p_R_Rtip1"].start : b["p_R_Rtip2"].stop].reshape(2, 3).copy()  # adjacent blocks
        return T_ER_Ntip, T_EL_Ptip, T_Ptip_I, rtips, self.image.spacing(nominal_spacing, x[b["scale"]])

    def start(self, initial: SequentialResult, nominal_spacing: FloatArray) -> tuple[FloatArray, dict[str, FloatArray]]:
        """``(x (P,), base)``: the starting point from the sequential result (its ``scaled_uv`` image
        calibration, else its first) and the starting rotations ``base`` that ``x``'s rotations are about."""
        image = initial.image.get("scaled_uv") or next(iter(initial.image.values()))
        base = {
            "R_ER_Ntip": initial.T_ER_Ntip[:3, :3],
            "R_EL_Ptip": initial.T_EL_Ptip[:3, :3],
            "R_Ptip_I": image.T_Ptip_I[:3, :3],
        }
        b = self.blocks()
        x = np.zeros(self.size)
        x[b["p_ER_Ntip"]] = initial.T_ER_Ntip[:3, 3]
        x[b["p_EL_Ptip"]] = initial.T_EL_Ptip[:3, 3]
        x[b["p_Ptip_I"]] = image.T_Ptip_I[:3, 3]
        x[b["p_R_Rtip1"]], x[b["p_R_Rtip2"]] = initial.p_R_Rtip["rtip1"], initial.p_R_Rtip["rtip2"]
        x[b["scale"]] = self.image.start_scale(image.spacing_m / nominal_spacing)
        return x, base

    def block_of(self, column: int) -> str:
        """The name of the block that holds column ``column`` of ``x``."""
        return next(name for name, s in self.blocks().items() if s.start <= column < s.stop)
