"""Update a stored calibration from a check instead of recalibrating (``brachycal verify --update``).

Where a check fails (:func:`~brachycal.calibration.verify.check.check_calibration`) and one part alone
explains it, that part's fitted change ``δ̂`` (the linearised least-squares fit of the check's
normalised residuals, with its SD from ``(J_hᵀJ_h)⁻¹``) is applied to the stored result:

- needle tip: ``p_ER_Ntip + δ̂`` (3, metres, flange frame);
- probe mount: ``T_EL_Ptip @ exp(δ̂)`` (translation ``v``, m, then rotation vector ``ω``, rad, at the
  probe tip), which carries the image with it;
- image transform: ``T_Ptip_I @ exp(δ̂)`` (at the image);
- image scale: ``s_u, s_v`` times ``1 + δ̂``.

The update is made only when the check determines it (:func:`update_refusal`): the part is fully
determined (rank = its parameter count), told apart from every other part (no tie, and a Bayes
factor of at least :data:`MIN_BAYES_FACTOR` over the runner-up), explains the whole check (what it
leaves is noise at the test's level), and is a small change (not a gross error). A robot change
is not updated from a check: identifying joint errors needs a whole session
(``calibrate --solve chain --identify-robot``). The updated result keeps the calibration's
leave-one-out figures and inputs (the next check's null) and records the update: the part, its
change and SD, the check session's files and the result it came from. The change was fitted on the
check's own samples: a new check with fresh samples confirms it.
"""

from __future__ import annotations

import copy
import datetime
from typing import TYPE_CHECKING

import numpy as np

from brachycal._version import __version__
from brachycal.calibration.verify.check import GROSS_PRIOR_MULTIPLES, calibrated_nominal_spacing, small_motion

if TYPE_CHECKING:
    from brachycal.calibration.session.result_file import ResultFile
    from brachycal.calibration.verify.check import CheckOutcome, CheckSession

#: The parts an update can change (the robot's joints need a whole session).
UPDATABLE = ("needle tip", "probe mount", "image transform", "image scale")
#: Least Bayes factor of the named part over the next most plausible one for an update: 20, "strong"
#: evidence on Kass and Raftery's scale (J. Am. Stat. Assoc. 90, 1995); a weaker margin could change
#: the wrong part.
MIN_BAYES_FACTOR = 20.0


def update_refusal(outcome: CheckOutcome) -> str | None:
    """Why the check cannot update the stored result (one line), or None when it can."""
    part = outcome.part
    if part is None:
        return "the calibration still holds: nothing to update"
    if part.part not in UPDATABLE:
        return (
            "a robot change is not updated from a check: recalibrate with a whole session "
            "(calibrate --solve chain --identify-robot)"
        )
    if part.prior_multiples > GROSS_PRIOR_MULTIPLES:
        return (
            f"no small change of one part explains the check (the {part.part} would move "
            f"{part.prior_multiples:.0f} prior SDs)"
        )
    if outcome.alternatives:
        alternatives = " or the ".join(outcome.alternatives)
        return f"the check cannot tell the {part.part} from the {alternatives} (a probe touch can)"
    if part.rank < part.parameters:
        return f"the check determines only {part.rank} of the {part.parameters} parameters of the {part.part}"
    if part.p_remaining < outcome.false_alarm:
        return (
            f"the {part.part} alone does not explain the check (what it leaves has p = {part.p_remaining:.2g}): "
            "more than one part may have moved"
        )
    others = [f for f in outcome.fits if f.part != part.part]
    if others:
        runner = max(others, key=lambda f: f.log_evidence)
        factor = float(np.exp(min(part.log_evidence - runner.log_evidence, 700.0)))
        if factor < MIN_BAYES_FACTOR:
            return (
                f"the check does not single out the {part.part}: Bayes factor {factor:.1f} over the {runner.part} "
                f"(an update needs {MIN_BAYES_FACTOR:g})"
            )
    return None


def updated_result(stored: ResultFile, outcome: CheckOutcome, session: CheckSession) -> dict[str, object]:
    """The stored result's file contents with the named part changed by its fitted change.

    Call only when :func:`update_refusal` gives None. Image updates apply to the checked method,
    and the result keeps only that method's image (the others would no longer agree with it).
    """
    part = outcome.part
    assert part is not None and update_refusal(outcome) is None, "update_refusal() first"
    raw = copy.deepcopy(stored.raw)
    method = outcome.method
    # The check refuses another scanner setting by the nominal spacing; once the image is updated the
    # rigid methods' spacing may no longer be it (or be gone): the file keeps it.
    nominal = calibrated_nominal_spacing(stored)
    if nominal is not None:
        raw["nominal_spacing_mm"] = (nominal * 1e3).tolist()
    transforms = raw["transforms"]
    d = np.asarray(part.delta, dtype=float)
    if part.part == "needle tip":
        T = stored.T_ER_Ntip.copy()
        T[:3, 3] += d
        transforms["ER_T_Ntip"] = T.tolist()
    elif part.part == "probe mount":
        transforms["EL_T_Ptip"] = (stored.T_EL_Ptip @ small_motion(d[:3], d[3:])).tolist()
    else:
        image = stored.image[method]
        if part.part == "image transform":
            transforms["Ptip_T_I"] = {method: (image.T_Ptip_I @ small_motion(d[:3], d[3:])).tolist()}
            raw["spacing_mm"] = {method: (image.spacing_m * 1e3).tolist()}
        else:
            transforms["Ptip_T_I"] = {method: image.T_Ptip_I.tolist()}
            raw["spacing_mm"] = {method: (image.spacing_m * (1.0 + d) * 1e3).tolist()}
    raw["update"] = {
        "from_result": {"file": stored.source, "sha256": stored.sha256},
        "check_session": {"folder": session.folder, "inputs": session.inputs},
        "date_utc": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "method": method,
        "part": part.part,
        "size": part.size_text(),
        "change": part.as_json(),
        "note": "fitted on the check's samples alone (its SD says how well they determine it); the leave-one-out "
        "figures and inputs are the original calibration's; confirm with a new check of fresh samples",
        "software": {"brachycal": __version__},
    }
    return raw
