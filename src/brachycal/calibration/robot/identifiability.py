"""Which robot-geometry parameters the data identify, and why not the others (the base set).

Every protocol (the dual-arm session, touches of fixed points, an external tracker) estimates the
``6 nq`` joint-origin corrections with a prior (the stated accuracy, or one the evidence chose).
This module says what the data actually determined: the robot columns of the normalised
identification Jacobian, in prior units and projected off the span of the protocol's own unknowns
(the session's tool/image/reference-tip parameters, the touched points, the tracker's frames; all
free), have a numerical rank (combinations the data see at all: the *structural* base set, as
FIGAROH's QR reduction finds it) and singular values; those at or above 1 are combinations the data
determine at least as well as the prior (*identified*). Per parameter, the posterior over the prior
SD says how much the data taught; for those they barely see, a pivoted QR and the projection tell
why: absorbed by the chain's own parameters, lumped with other joints' corrections, or seen but
too weakly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from brachycal.se3 import FloatArray

#: Names of the 6 components of one joint's correction, in order.
COMPONENTS = ("vx", "vy", "vz", "wx", "wy", "wz")
#: A combination is "identified" when the data's information on it at least equals the prior's
#: (its SD from the data alone is at most the stated accuracy): eigenvalue ≥ 1 in prior units.
IDENTIFIED_INFORMATION = 1.0
#: Structural rank: singular values of the prior-scaled, tool-projected Jacobian below this times
#: the largest are exact null directions (data that can never see them, whatever the noise). The
#: robot columns come from central differences (relative errors ~1e-10): on the real-arm twin
#: (seed 0) the spectrum falls from 1.6e-6 straight to 6.9e-11 and below (32 of 90 values), and
#: 1e-8 sits in that gap, a factor ~100 from either side.
STRUCTURAL_RCOND = 1e-8
#: A parameter's posterior SD above this fraction of its prior SD: the data barely see it.
NOT_IDENTIFIED_RATIO = 0.9
#: A column whose part outside the tool/image parameters' span is below this fraction of its norm
#: is absorbed by them (e.g. the last joint's origin, which moves the tools rigidly).
ABSORBED_FRACTION = 0.05


@dataclass(frozen=True)
class Identifiability:
    """Which robot parameters the data determine (beyond the prior).

    Attributes:
        structural_rank: combinations of the ``6 nq`` corrections that the data see at all, once
            the protocol's own unknowns are free (numerical rank of the projected Jacobian).
        identified: combinations the data determine at least as well as the prior.
        posterior_ratio: ``(nq, 6)`` posterior SD over prior SD per parameter (1: not seen).
        reasons: ``"joint.component"`` → why it is not identifiable, for each parameter whose ratio
            exceeds :data:`NOT_IDENTIFIED_RATIO`.
    """

    structural_rank: int
    identified: int
    posterior_ratio: FloatArray
    reasons: dict[str, str]

    def summary(self, joint_names: tuple[str, ...]) -> list[str]:
        """Lines a person can read: the counts, then the unidentified parameters grouped by joint."""
        n = 6 * len(joint_names)
        lines = [
            f"{self.identified} of {n} robot-geometry combinations identified beyond the prior "
            f"({self.structural_rank} seen at all by these data)"
        ]
        by_joint: dict[str, list[str]] = {}
        for key, why in self.reasons.items():
            joint, component = key.rsplit(".", 1)
            by_joint.setdefault(f"{joint}: {why}", []).append(component)
        for head, components in by_joint.items():
            joint, why = head.split(": ", 1)
            lines.append(f"  {joint} {','.join(components)}: {why}")
        return lines


def identifiability(
    J: FloatArray,
    p: int,
    scale: FloatArray,
    posterior: FloatArray,
    joint_names: tuple[str, ...],
    *,
    nuisance: str = "the tool, image and reference-tip parameters",
) -> Identifiability:
    """The base-set analysis of the normalised data Jacobian ``J = [J_θ, J_c · scale]`` (``p`` chain
    columns): the robot columns projected off the chain parameters' span (which are free), their
    singular values in prior units (structural rank, identified count), and per parameter its
    posterior/prior SD ratio with the reason when the data barely see it. ``nuisance`` names the
    ``p`` other parameters in the reasons (absorbed by them)."""
    J_t, J_c = J[:, :p], J[:, p:]
    Q, _ = np.linalg.qr(J_t)
    projected = J_c - Q @ (Q.T @ J_c)
    s = np.linalg.svd(projected, compute_uv=False)
    structural = int(np.sum(s > s[0] * STRUCTURAL_RCOND)) if s.size and s[0] > 0 else 0
    identified = int(np.sum(s**2 >= IDENTIFIED_INFORMATION))
    ratio = np.sqrt(np.clip(np.diag(posterior[p:, p:]), 0.0, None))  # prior units: SD / prior SD
    # Columns that other corrections can stand in for: pivoted QR ranks the independent ones first.
    _, _, pivots = scipy.linalg.qr(projected, mode="economic", pivoting=True)
    independent = set(pivots[:structural].tolist())
    column_norm = np.linalg.norm(J_c, axis=0)
    outside = np.linalg.norm(projected, axis=0)
    reasons = {}
    for k in np.flatnonzero(ratio > NOT_IDENTIFIED_RATIO):
        name = f"{joint_names[k // 6]}.{COMPONENTS[k % 6]}"
        if column_norm[k] <= 1e-12 * max(column_norm.max(), 1e-300):
            reasons[name] = "no recorded datum moves it"
        elif outside[k] < ABSORBED_FRACTION * column_norm[k]:
            reasons[name] = f"absorbed by {nuisance}"
        elif k not in independent:
            reasons[name] = "its effect equals a combination of other joints' corrections (lumped with them)"
        else:
            reasons[name] = "seen, but less than the prior: the poses vary this joint too little"
    return Identifiability(structural, identified, ratio.reshape(-1, 6), reasons)
