"""Order selection with the refinement (:mod:`stillframe.identification.order_selection`): the
Hankel gap
proposes, BIC over the refined candidates decides (issue 12)."""

from __future__ import annotations

from stillframe.identification.pipeline import identify
from stillframe.identification.sweep import score, shear_building, simulate


def test_bic_over_refined_candidates_corrects_the_hankel_gap() -> None:
    """A 4-storey building (true order 8) at 30 dB, 1024 samples: the refined candidates around
    the Hankel gap's order give BIC its minimum at the true order, the four modes are within 0.2 %
    and 10 %, and no check fires. (Before the records were normalised to unit RMS, the Hankel gap
    alone picked 10 here; on the normalised records it picks 8 as well, so this case no longer
    shows BIC correcting the gap.)"""
    building = shear_building(4)
    rec = simulate(building, 1024, 30.0, 4)
    plain = identify(rec.u, rec.y, rec.dt, "okid-eradc", "auto", refine=False)
    refined = identify(rec.u, rec.y, rec.dt, "okid-eradc", "auto", refine=True)
    assert plain.order == 8
    assert refined.order == 2 * building.frequency_hz.size == 8
    result = score(refined.modes.frequency_hz, refined.modes.damping_ratio,
                   building.frequency_hz, building.damping_ratio)
    assert result["missed"] == 0
    assert result["frequency_error"] < 2e-3 and result["damping_error"] < 0.1
    assert refined.warnings == ()
