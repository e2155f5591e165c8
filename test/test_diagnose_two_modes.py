"""Diagnosis of a stage with two lightly damped modes (generated hold-out family 20, found by the benchmark)."""
from __future__ import annotations


def test_two_modes_are_named_dynamics_not_a_delay():
    """GMA stage, a tenth of the motion through modes at 477 and 843 Hz behind one hold (case 2000147, 153× the
    noise). With one mode only, the mode refitted to 3–6× the noise floor and a delay imitated the pair as well:
    'delay' was named. With two modes in cascade (dynamics.modes: 2) both are found and the error reaches the
    noise floor."""
    from hyst_model.diagnose.diagnose import diagnose
    from hyst_sim.generator import generate_case
    c = generate_case(2000147, "single_large")
    assert c.expected == ("dynamics",) and c.forms[0][0] == "mode2"
    d = diagnose(c.t, c.u, c.y)
    assert d.missing == "dynamics", d.explanation
    m, th = d.models[d.ladder[1].model]
    assert m.config()["dynamics.modes"] == 2.0
    fn = sorted((m.unpack(th)["dynamics.fn"], m.unpack(th)["dynamics.fn2"]))
    assert abs(fn[0] / 477.1 - 1) < 0.03 and abs(fn[1] / 843.5 - 1) < 0.03, fn
    assert d.ladder[1].rmse < 1.3 * d.noise, d.explanation
    assert "modes 2" in d.candidates[0].evidence
