"""The exchange step after the ladder (hyst_model.diagnose.swap)."""
from __future__ import annotations

import pytest

pytestmark = pytest.mark.slow


def test_a_mode_taken_for_a_delay_at_the_first_rung_is_exchanged():
    """Generated sweep with a sensor delay and a linear drift (accuracy family 9, case 91, found by the
    benchmark): at the first rung a 3-parameter mode (11.7 nm) beat the 1-parameter delay (13.8 nm) because it
    also bent towards the drift; drift on top of the mode then reached the noise floor, and the answer was
    "dynamics + drift". With the mode exchanged for the delay the model validates alike (1.64 nm) with two
    parameters fewer: "delay + drift"."""
    from hyst_model.diagnose.diagnose import diagnose
    from hyst_sim.generator import generate_case
    c = generate_case(900091, "pair")
    d = diagnose(c.t, c.u, c.y)
    assert set(c.expected) == {"delay", "drift"}
    assert {r.effect for r in d.candidates[:2]} == {"delay", "drift"}, d.explanation
    assert sorted(d.ladder[-1].effects) == ["delay", "drift"], d.explanation
    dyn = next(r for r in d.candidates if r.effect == "dynamics")
    assert not dyn.significant and "exchanged for delay" in dyn.evidence, dyn.evidence
    # never backwards: the exchanged model validates as the one it replaced (within the paired test's reach)
    before = next(r for r in d.ladder if sorted(r.effects) == ["drift", "dynamics"])
    assert d.ladder[-1].rmse <= 1.1 * before.rmse
    assert d.ladder[-1].rmse < 1.5 * d.noise


def test_no_exchange_with_a_single_effect():
    """With one effect the first rung compared every candidate on the same footing already: nothing to do."""
    from hyst_model.diagnose.swap import swap
    ladder, models, chosen = [], {}, ["delay"]
    out, changed = swap(None, ladder, models, chosen, {}, {})  # type: ignore[arg-type]
    assert out == ["delay"] and not changed and ladder == [] and models == {}
