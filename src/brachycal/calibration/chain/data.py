"""The session's data as the chain sees them: flange poses of every datum, computed once."""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from brachycal.calibration.chain.image_models import ImageModel
from brachycal.data.session import Session
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray

#: Axes moves: (point, the column of the tool's rotation it moves along, the two columns its
#: residual is measured along). Each tool (needle, probe) has both.
AXES_MOVES = ((1, 1, [0, 2]), (2, 2, [0, 1]))
#: Residual rows of the axes moves: two tools, each move measured across two columns.
N_AXES_ROWS = 2 * sum(len(across) for _, _, across in AXES_MOVES)


@dataclass(frozen=True)
class ChainData:
    """Flange poses of every datum, computed once (the model's forward kinematics).

    Poses are ``T_R_E`` ``(4, 4)`` stacks in the robot's base frame, metres (``E`` the rig's needle
    flange ER or probe flange EL): the touches per tool as
    ``(reference index, (T, 4, 4))`` pairs, the axes moves at p1, p2, p3 ``(3, 4, 4)``, both flanges
    at every image sample ``(N, 4, 4)``, with the annotated pixels ``uv_px (N, 2)`` and the scanner's
    nominal spacing ``spacing_m (2,)`` (metres per pixel).
    """

    p_ER_Mtip: FloatArray
    top: list[tuple[int, FloatArray]]  # (reference index, T_R_ER (T, 4, 4))
    needle: list[tuple[int, FloatArray]]
    probe: list[tuple[int, FloatArray]]
    needle_axes: FloatArray  # (3, 4, 4) T_R_ER at p1, p2, p3
    probe_axes: FloatArray
    T_R_ER: FloatArray  # (N, 4, 4) image samples
    T_R_EL: FloatArray
    uv_px: FloatArray
    spacing_m: FloatArray

    @classmethod
    def of(cls, session: Session, robot: Robot, offsets: FloatArray | None = None) -> ChainData:
        """The session's poses through ``robot``, with joint zero ``offsets (nq,)`` (radians) added."""
        shift = np.zeros(robot.nq) if offsets is None else offsets
        needle_flange, probe_flange = robot.rig.needle_flange, robot.rig.probe_flange  # the paper's ER and EL

        def fk(flange: str, q: FloatArray) -> FloatArray:
            return robot.fk(flange, np.atleast_2d(q) + shift)

        touches = {
            tool: [
                (k, fk(needle_flange if tool != "probe" else probe_flange, session.touches[tool, ref].q))
                for k, ref in enumerate(("rtip1", "rtip2"))
            ]
            for tool in ("top_model", "needle", "probe")
        }
        return cls(
            p_ER_Mtip=session.p_ER_Mtip,
            top=touches["top_model"],
            needle=touches["needle"],
            probe=touches["probe"],
            needle_axes=fk(needle_flange, np.array([session.axes["needle"][p] for p in ("p1", "p2", "p3")])),
            probe_axes=fk(probe_flange, np.array([session.axes["probe"][p] for p in ("p1", "p2", "p3")])),
            T_R_ER=fk(needle_flange, session.samples_q),
            T_R_EL=fk(probe_flange, session.samples_q),
            uv_px=session.uv_px,
            spacing_m=session.spacing_m,
        )

    def subset(self, samples: np.ndarray) -> ChainData:
        """The same data with only the image samples where ``samples (N,)`` is true."""
        return replace(self, T_R_ER=self.T_R_ER[samples], T_R_EL=self.T_R_EL[samples], uv_px=self.uv_px[samples])

    @cached_property
    def touch_T(self) -> FloatArray:
        """``(M, 4, 4)`` flange poses of every touch: top-model, needle, probe; rtip1 then rtip2."""
        return np.concatenate([T for touches in (self.top, self.needle, self.probe) for _, T in touches])

    @cached_property
    def touch_tool(self) -> np.ndarray:
        """``(M,)`` which tool each touch holds: 0 top-model, 1 needle, 2 probe."""
        return np.concatenate(
            [np.full(len(T), i) for i, touches in enumerate((self.top, self.needle, self.probe)) for _, T in touches]
        )

    @cached_property
    def touch_ref(self) -> np.ndarray:
        """``(M,)`` which reference tip each touch touched: 0 rtip1, 1 rtip2."""
        return np.concatenate(
            [np.full(len(T), k) for touches in (self.top, self.needle, self.probe) for k, T in touches]
        )

    @cached_property
    def axes_T(self) -> FloatArray:
        """``(2, 3, 4, 4)`` the axes moves' flange poses, needle then probe (p1, p2, p3 each)."""
        return np.stack([self.needle_axes, self.probe_axes])

    @cached_property
    def axes_terms(self) -> tuple[FloatArray, FloatArray, np.ndarray, np.ndarray]:
        """The axes moves' constant parts, one row per residual (:data:`AXES_MOVES`, tool-major):
        ``A (2, R, 3, 3) = R_a0ᵀ (R_ai − R_a0)`` and ``b (2, R, 3) = R_a0ᵀ (t_ai − t_a0)`` of the row's move
        from p1 to point ``i``, so that the move of a tip ``p`` in the p1 flange frame is ``A p + b``; the
        row's ``points (R,)`` and the tool's ``columns (R,)`` it is measured along (``R`` = 4)."""
        points = np.array([point for point, _, across in AXES_MOVES for _ in across])
        columns = np.array([c for _, _, across in AXES_MOVES for c in across])
        R_a, t_a = self.axes_T[:, :, :3, :3], self.axes_T[:, :, :3, 3]  # (2, 3, 3, 3), (2, 3, 3)
        R_a0_T = np.swapaxes(R_a[:, 0], -1, -2)[:, None]  # (2, 1, 3, 3)
        A = R_a0_T @ (R_a[:, points] - R_a[:, :1])
        b = (R_a0_T @ (t_a[:, points] - t_a[:, :1])[..., None])[..., 0]
        return A, b, points, columns

    @cached_property
    def _touch_jacobian(self) -> dict[int, FloatArray]:
        # The touches' Jacobian rows do not depend on x: computed once per parameter-vector length.
        return {}

    def touch_jacobian(self, size: int, blocks: dict[str, slice]) -> FloatArray:
        """``(3 T, size)`` Jacobian of the touch residuals ``R p_tool + t − rtip`` (metres, unweighted):
        ``R`` in the tool tip's columns, ``−I`` in the reference tip's. Constant; computed once per
        parameter-vector length (read only)."""
        if size not in self._touch_jacobian:
            touch = np.zeros((len(self.touch_tool), 3, size))
            R_touch = self.touch_T[:, :3, :3]
            for tool, name in ((1, "p_ER_Ntip"), (2, "p_EL_Ptip")):
                touch[self.touch_tool == tool, :, blocks[name]] = R_touch[self.touch_tool == tool]
            for k, name in enumerate(("p_R_Rtip1", "p_R_Rtip2")):
                touch[self.touch_ref == k, :, blocks[name]] = -np.eye(3)
            rows = touch.reshape(-1, size)
            rows.flags.writeable = False
            self._touch_jacobian[size] = rows
        return self._touch_jacobian[size]

    @cached_property
    def _spacing_columns(self) -> dict[str, list[FloatArray]]:
        return {}

    def spacing_columns(self, image: ImageModel) -> list[FloatArray]:
        """``image.spacing_columns`` of these samples' pixels at the nominal spacing: constant, computed
        once per image model (read only)."""
        if image.name not in self._spacing_columns:
            columns = image.spacing_columns(self.uv_px, self.spacing_m)
            for d in columns:
                d.flags.writeable = False
            self._spacing_columns[image.name] = columns
        return self._spacing_columns[image.name]

    @property
    def n_touch_rows(self) -> int:
        return 3 * len(self.touch_tool)

    def group_rows(self, n_images: int) -> dict[str, slice]:
        """Rows of each residual group in :func:`~brachycal.calibration.chain.chain_residuals` with
        ``n_images`` samples used: touches (3 per touch), axes moves, images (3 per sample)."""
        t = self.n_touch_rows
        a = t + N_AXES_ROWS
        return {"touch": slice(0, t), "axes": slice(t, a), "image": slice(a, a + 3 * n_images)}
