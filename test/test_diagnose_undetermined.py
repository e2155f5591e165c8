"""What a record cannot tell apart is said, with numbers (hyst_model.diagnose.undetermined), on generated records
unlike the library's forms (hyst_sim.generator). The note changes no answer."""
from __future__ import annotations

import json

import pytest

from hyst_model.diagnose.diagnose import diagnose
from hyst_model.diagnose.undetermined import CONTRIBUTION
from hyst_sim.generator import generate_case


def test_a_delay_the_base_takes_on_sines_is_said_to_be_undetermined(tmp_path):
    """GMA stage, a fractional input delay, excited by a few sines (case 2000149, 29× the noise): the MBW's memory
    terms take the phase, the base validates at the noise floor and the answer is "none" — but on a fresh record
    the base alone errs 14× more than with the delay. The note names the delay and its fitted size."""
    c = generate_case(2000149, "single_small")
    assert c.expected == ("delay",) and c.excitation == "sines"
    d = diagnose(c.t, c.u, c.y)
    assert d.missing == "none", d.explanation
    und = {x.effect: x for x in d.undetermined}
    assert "delay" in und and und["delay"].against == "the base", d.explanation
    assert und["delay"].contribution >= CONTRIBUTION and und["delay"].params["delay.tau"] > 0
    assert "does not determine delay" in d.explanation and "hyst excite" in d.explanation
    js = json.loads(json.dumps(d.to_json()))
    assert any(x["effect"] == "delay" for x in js["undetermined"])
    _the_advised_command_runs(d.explanation, c, tmp_path)


def _the_advised_command_runs(explanation, c, tmp_path):
    """The ``hyst excite`` command the note gives runs as printed and writes an excitation at the record's rate
    and within its reach, which hyst_excite_node's default limits for that profile accept."""
    import numpy as np
    from hyst_common.profiles import GMA_LIMITS, PEA_LIMITS
    from hyst_control.excitation import ExcitationSpec, from_samples
    from hyst_model.cli.main import main as hyst
    from hyst_model.io.csvio import read_input_csv
    words = explanation[explanation.index("hyst excite"):].split(" writes one")[0].split()
    assert words[words.index("--out") + 1] == "excite.csv"
    out = tmp_path / "excite.csv"
    words[words.index("--out") + 1] = str(out)
    assert hyst(words[1:]) == 0, words
    t, u = read_input_csv(out)
    dt = float(c.t[1] - c.t[0])
    assert np.allclose(np.diff(t), dt)
    reach = max(abs(c.u.min()), abs(c.u.max()))
    assert np.max(np.abs(u)) <= reach and np.max(np.abs(u)) > 0.5 * reach
    lim = GMA_LIMITS if c.u.min() < 0 else PEA_LIMITS
    from_samples(t, u, ExcitationSpec(v_min=lim.v_min, v_max=lim.v_max, slew_max=float(min(lim.slew_max, 1e9)),
                                      dt=dt))


@pytest.mark.parametrize("seed", [2700002, 2000002])
def test_records_without_an_effect_get_no_note(seed):
    """Steps (2700002) and triangles (2000002) without an effect: every fitted effect's part of the output stays
    under CONTRIBUTION × the noise (largest seen 1.6×), so nothing is said to be undetermined."""
    c = generate_case(seed, "none")
    d = diagnose(c.t, c.u, c.y)
    assert d.missing == "none" and d.undetermined == [], d.explanation
    assert "does not determine" not in d.explanation


def test_an_effect_that_validates_alike_with_the_one_named_is_said():
    """GMA stage with two modes at 3× the noise floor on band-limited noise (case 2700171): a delay and a mode seen
    below its resonance validate alike (both at the noise floor); delay, the simpler, is named, and the note says
    the record does not tell it from dynamics."""
    c = generate_case(2700171, "single_large")
    assert c.expected == ("dynamics",)
    d = diagnose(c.t, c.u, c.y)
    assert d.missing == "delay", d.explanation
    und = {x.effect: x for x in d.undetermined}
    assert "dynamics" in und and und["dynamics"].against == "delay", d.explanation
    assert "does not tell delay from: dynamics" in d.explanation
