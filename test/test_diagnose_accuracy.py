"""A fixed subset of the accuracy benchmark (bench/bench_diagnose_accuracy.py) as tests.

Seeds are the first of each kind in family seed 42 — not chosen for passing. What holds on held-out families
is asserted (no false alarm on 'none'; never a bare 'none' when the base error is ≥ 2× the noise; the first four
large single effects named first). The rates over 200 cases are in the README (bench_diagnose_accuracy).
"""
from __future__ import annotations

import pytest

pytestmark = pytest.mark.slow

FAMILY = 42


def _run(i: int, kind: str) -> dict:
    import importlib.util
    from pathlib import Path
    spec = importlib.util.spec_from_file_location(
        "bench_acc", Path(__file__).resolve().parents[1] / "bench" / "bench_diagnose_accuracy.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.run_case((FAMILY * 100000 + i, kind))


def _noise_margin() -> float:
    """diagnose's own margin: a base within it of the noise floor is answered 'none'."""
    import inspect
    from hyst_model.diagnose.diagnose import diagnose
    return float(inspect.signature(diagnose).parameters["noise_margin"].default)


@pytest.mark.parametrize("i", [0, 1, 2])
def test_no_false_alarm_on_none(i):
    r = _run(i, "none")
    assert r["named"] == ["none"], r


@pytest.mark.parametrize("i,kind", [(0, "outside"), (1, "outside"), (0, "pi_truth"), (1, "pi_truth")])
def test_a_large_error_is_never_a_bare_none(i, kind):
    from hyst_model.diagnose.unexplained import UNEXPLAINED_FACTOR
    r = _run(i, kind)
    if r["base_over_noise"] >= UNEXPLAINED_FACTOR:
        assert r["named"][0] != "none" and (r["missing"] == "unexplained" or r["unexplained"] is not None), r
    elif r["base_over_noise"] <= _noise_margin():
        assert r["named"] == ["none"], r


@pytest.mark.parametrize("i", [0, 1, 2, 3])
def test_large_single_effect_is_named_first(i):
    r = _run(i, "single_large")
    assert r["named"][0] == r["expected"][0], r


@pytest.mark.parametrize("seed", [300045, 300070])
def test_a_base_fit_in_a_poor_basin_is_no_false_alarm(seed):
    """Records without any effect whose first base fit ended 3.9–4.2× the noise (hold-out family 3, found by the
    benchmark): an effect that let the joint fit leave that basin was named. The base refitted from the joint
    refits' base parameters (stages.rebase) reaches the floor, and the answer is 'none'."""
    from hyst_model.diagnose.diagnose import diagnose
    from hyst_sim.generator import generate_case
    c = generate_case(seed, "none")
    d = diagnose(c.t, c.u, c.y)
    assert d.missing == "none", d.explanation
    assert d.baseline_rmse < 1.5 * d.noise


def test_candidates_are_judged_again_once_the_base_left_a_poor_basin():
    """Generated drift + two stage modes on steps (family 1, found by the benchmark): the first base fit ended
    at 6.7 µm, the joint refit with a delay at 208 nm, and the base refitted from there at 104 nm — against which
    every candidate of the first round looked worse: "unexplained" at 80× the noise. Screened and refitted again
    from the better base, the mode is found and the error falls (stages._rescreen)."""
    from hyst_model.diagnose.diagnose import diagnose
    from hyst_sim.generator import generate_case
    c = generate_case(100127, "pair")
    d = diagnose(c.t, c.u, c.y)
    assert d.missing == "dynamics", d.explanation
    assert d.ladder[-1].rmse < 0.7 * d.baseline_rmse, d.explanation


def test_a_steps_record_is_validated_on_some_of_its_steps():
    """Generated GMA stage, 8 steps with holds and a lightly damped mode ringing after each (development family
    11, found by its fresh-record column): the unshifted hold-out blocks held none of the steps, so the base
    validated at 1.02× the noise floor (training 10.6×) and the answer was 'none' while the base missed the fresh
    record by 13×. With the blocks placed on a fair share of the input's changes (identify.result.block_phase),
    the mode is found and cuts the validation error."""
    import numpy as np
    from hyst_model.diagnose.diagnose import diagnose
    from hyst_model.identify import block_mask
    from hyst_sim.generator import generate_case
    c = generate_case(1100087, "single_large")
    assert not np.any(block_mask(c.t.size)[1:][np.abs(np.diff(c.u)) > 0])  # the case: no step validated
    d = diagnose(c.t, c.u, c.y)
    assert d.missing == "dynamics", d.explanation
    assert d.ladder[-1].rmse < 0.3 * d.baseline_rmse, d.explanation


def test_a_rung_screens_each_effect_from_its_own_start_too():
    """Generated GMA stage, a gain kink and a soft two-sided limit (development family 11): the limit alone on the
    base ended 285 µm below the stroke, and those values, carried onto the kink's rung as the screen's start, gave
    no gradient — the screen stayed at the rung's 37.1 nm and the limit was never taken. Screened from the rung's
    own start as well (stages.screen_on keeps the better), the kink + limit reach 1.2× the noise floor."""
    from hyst_model.diagnose.diagnose import diagnose
    from hyst_sim.generator import generate_case
    c = generate_case(1100030, "pair")
    d = diagnose(c.t, c.u, c.y)
    assert set(d.ladder[-1].effects) == {"asymmetry", "saturation"}, d.explanation
    assert d.ladder[-1].rmse < 2.0 * d.noise, d.explanation


def test_a_base_that_does_not_carry_over_within_a_short_record_is_flagged():
    """Generated GMA stage with no effect, 4 s at 5 kHz, five steps (a family at another sampling than the
    benchmark's): the base fits its training part to 1.5× the noise floor and the held-out part to 13×, and creep
    was named with nothing said. The diagnosis now cautions that the record does not determine the base; the
    answer itself is not changed. The benchmark's own effect-free record gets no caution."""
    from hyst_model.diagnose.diagnose import diagnose
    from hyst_sim.generator import generate_case
    c = generate_case(1600045, "none", rate=5000.0, duration=4.0)
    d = diagnose(c.t, c.u, c.y)
    assert d.baseline_rmse > 3.0 * max(d.baseline_rmse_train, d.noise)  # the case
    assert d.caution is not None and "does not determine the base" in d.explanation
    assert d.to_json()["caution"] == d.caution
    c0 = generate_case(FAMILY * 100000, "none")
    assert diagnose(c0.t, c0.u, c0.y).caution is None
