"""The scenario generator (hyst_sim.generator): deterministic, calibrated, within the actuator's limits."""
from __future__ import annotations

import numpy as np
import pytest

from hyst_sim.generator import FORMS, KINDS, case_family, generate_case
from hyst_sim.generator.forms import LIBRARY_NAME
from hyst_common.profiles import GMA, PEA


def test_same_seed_same_arrays_other_seed_other_arrays():
    a, b, c = generate_case(11, "pair"), generate_case(11, "pair"), generate_case(12, "pair")
    np.testing.assert_array_equal(a.y, b.y)
    np.testing.assert_array_equal(a.u_fresh, b.u_fresh)
    assert a.name == b.name and not np.array_equal(a.y, c.y)


@pytest.mark.parametrize("seed", range(30))
def test_cases_are_labelled_sized_and_within_limits(seed):
    c = generate_case(seed)
    assert c.kind in KINDS
    lim = GMA if c.u.min() < 0 else PEA
    assert lim.v_min - 1e-9 <= c.u.min() and c.u.max() <= lim.v_max + 1e-9
    assert np.all(np.isfinite(c.y)) and np.all(np.isfinite(c.y_fresh))
    assert not np.array_equal(c.y, c.y_fresh)                       # fresh noise at least
    if c.kind == "single_small":
        assert 2.9 <= c.size_over_noise[0] <= 5.1, c.size_over_noise   # calibrated to 3–5× the noise σ
    if c.kind == "single_large":
        assert c.size_over_noise[0] >= 4.9, (c.name, c.size_over_noise)
    for f, _ in c.forms:
        assert f in FORMS
    if c.kind in ("single_large", "single_small", "pair"):
        assert c.expected == tuple(LIBRARY_NAME[f] for f, _ in c.forms)
        assert "unexplained" not in c.expected
    if c.kind == "outside":
        assert c.expected == ("unexplained",)


@pytest.mark.parametrize("seed, kind", [(500048, "single_large"), (100017, "single_small"), (500126, "pair")])
def test_a_gain_kink_lies_within_the_recorded_stroke(seed, kind):
    """These cases once drew the kink above the stroke their record covers: labelled with an effect of size 0."""
    c = generate_case(seed, kind)
    (i,) = [k for k, (f, _) in enumerate(c.forms) if f == "asym_kink"]
    assert c.size_over_noise[i] >= (2.9 if kind == "single_small" else 4.9), (c.name, c.size_over_noise)


def test_family_is_balanced_over_kinds():
    fam = case_family(24, seed=3)
    kinds = {c.kind for c in fam}
    assert kinds == set(KINDS)
    assert len({c.name for c in fam}) == 24


@pytest.mark.parametrize("forms", ["own", "alt"])
def test_every_form_changes_the_output_and_scales_with_strength(forms):
    """Each form (the benchmark's own, and the other laws of ``effect_forms="alt"``) changes the output, more when
    stronger, and stays finite."""
    from hyst_model.core import stage_model
    from hyst_sim.generator.forms import Ctx, draw
    from hyst_sim.generator.forms_alt import ALT_FORMS, draw_alt
    rng = np.random.default_rng(0)
    t = np.arange(8000) / 2000.0
    u = 75 + 60 * np.sin(2 * np.pi * 1.5 * t) * np.clip(t / 0.2, 0, 1)
    sim = stage_model("pea").simulate
    x = sim(u)
    for name, (fn, _) in (FORMS if forms == "own" else ALT_FORMS).items():
        c = Ctx(t, u, sim, x, 30e-6, draw(name, rng, 4.0, 2000.0) if forms == "own" else draw_alt(rng, 2000.0))
        small = np.sqrt(np.mean((fn(c, 0.2)[1] - x) ** 2))
        large = np.sqrt(np.mean((fn(c, 1.0)[1] - x) ** 2))
        assert np.all(np.isfinite(fn(c, 1.0)[1])) and large > 1e-9 and large > small, name


def test_other_rates_and_lengths_give_other_families_and_the_default_is_unchanged():
    """Hold-out families at another sampling (bench_diagnose_accuracy --rate/--duration) — and the benchmark's
    own family (2 kHz, 8 s) draws the same case with or without the arguments."""
    a = generate_case(77, "single_large")
    b = generate_case(77, "single_large", rate=2000.0, duration=8.0)
    assert a.t.size == 16000 and np.array_equal(a.y, b.y) and a.forms == b.forms
    c = generate_case(77, "single_large", rate=1000.0, duration=20.0)
    assert c.t.size == 20000 and np.isclose(c.t[1] - c.t[0], 1e-3)
    assert np.isclose(c.t_fresh[-1], c.t[-1]) and c.u_fresh.size == c.y_fresh.size == 20000
    assert all(s > 0 for s in c.size_over_noise)
    with pytest.raises(ValueError, match="1000 samples"):
        generate_case(77, "none", rate=100.0, duration=2.0)


@pytest.mark.parametrize("rate", [1000.0, 5000.0])
def test_a_mode_lies_below_the_sampling_rate(rate):
    from hyst_sim.generator.forms import draw
    rng = np.random.default_rng(5)
    fns = [draw("mode1", rng, 8.0, rate)["fn"] for _ in range(200)]
    assert max(fns) <= 0.35 * rate and min(fns) >= 120.0


def test_wide_shapes_are_admissible_stages_of_the_profiles_stroke():
    """The "wide" truth family (other actuators): Remark 4.1 holds, the loop is 3-25 % wide and the full-range
    response is the profile's stroke within ±20 %; the benchmark's own family is unchanged."""
    from hyst_sim.generator.cases import _wide_truth
    rng = np.random.default_rng(3)
    for prof_name, prof in (("pea", PEA), ("gma", GMA)):
        for _ in range(5):
            p = _wide_truth(prof_name, rng)
            assert p.alpha1 < -abs(p.psi1) and p.alpha2 < -abs(p.psi2)
            t = np.arange(4000) / 2000.0
            u = prof.v_min + (prof.v_max - prof.v_min) * (0.5 + 0.5 * np.sin(2 * np.pi * t))
            y = p.simulate(u)[2000:]
            assert 0.75 * prof.stroke <= np.ptp(y) <= 1.25 * prof.stroke
    a = generate_case(9, "single_large", shapes="wide")
    b = generate_case(9, "single_large")
    assert a.forms[0][0] != "" and not np.array_equal(a.y, b.y)
    with pytest.raises(ValueError, match="shapes"):
        generate_case(9, "none", shapes="narrow")


def test_the_alternative_forms_name_the_library_and_keep_the_travel_monotonic():
    """The other laws cover every library effect under other names; the softening at the ends and the exponential
    sensor gain keep the travel monotonic."""
    from hyst_model.core import stage_model
    from hyst_sim.generator.forms import Ctx
    from hyst_sim.generator.forms_alt import ALT_FORMS, ALT_LIBRARY_NAME, asym_exp, draw_alt, sat_cubic
    assert set(ALT_LIBRARY_NAME.values()) == set(LIBRARY_NAME.values()) - {"unexplained"}
    assert not set(ALT_FORMS) & set(FORMS)
    t = np.arange(8000) / 2000.0
    u = 75 + 60 * np.sin(2 * np.pi * 1.5 * t) * np.clip(t / 0.2, 0, 1)
    sim = stage_model("pea").simulate
    x = sim(u)
    order = np.argsort(x)
    rng = np.random.default_rng(1)
    for form in (sat_cubic, asym_exp, asym_exp, asym_exp):
        c = Ctx(t, u, sim, x, 30e-6, draw_alt(rng, 2000.0))
        assert np.all(np.diff(form(c, 1.0)[1][order]) >= -1e-18)   # float ties


@pytest.mark.parametrize("seed", range(12))
def test_alternative_forms_families_are_labelled_and_the_own_family_is_unchanged(seed):
    from hyst_sim.generator.cases import family_kinds
    from hyst_sim.generator.forms_alt import ALT_FORMS, ALT_LIBRARY_NAME
    kind = family_kinds(12)[seed]
    a = generate_case(seed, kind, effect_forms="alt")
    assert np.all(np.isfinite(a.y)) and np.all(np.isfinite(a.y_fresh))
    if kind in ("single_large", "single_small", "pair"):
        assert all(f in ALT_FORMS for f, _ in a.forms)
        assert a.expected == tuple(ALT_LIBRARY_NAME[f] for f, _ in a.forms)
    own, default = generate_case(seed, kind, effect_forms="own"), generate_case(seed, kind)
    assert np.array_equal(own.y, default.y) and own.forms == default.forms
    with pytest.raises(ValueError, match="effect_forms"):
        generate_case(seed, kind, effect_forms="other")


@pytest.mark.parametrize("seed", range(12))
def test_alternative_excitations_stay_in_range_cover_the_same_part_fresh_and_leave_the_own_family_unchanged(seed):
    from hyst_common.profiles import GMA, PEA
    from hyst_sim.generator.cases import family_kinds
    from hyst_sim.generator.excitation_alt import ALT_EXCITATIONS
    kind = family_kinds(12)[seed]
    a = generate_case(seed, kind, excitations="alt")
    assert a.excitation in ALT_EXCITATIONS
    prof = PEA if a.u.min() >= 0 else GMA
    assert prof.v_min <= a.u.min() and a.u.max() <= prof.v_max
    assert np.all(np.isfinite(a.y)) and np.all(np.isfinite(a.y_fresh))
    assert not np.array_equal(a.u, a.u_fresh)                         # a new realisation ...
    after = a.t >= 0.2                                                 # ... over the same part of the range
    lo, hi = np.percentile(a.u[after], [1, 99])
    lo_f, hi_f = np.percentile(a.u_fresh[after], [1, 99])
    span = prof.v_max - prof.v_min
    assert abs(lo - lo_f) < 0.25 * span and abs(hi - hi_f) < 0.25 * span
    own, default = generate_case(seed, kind, excitations="own"), generate_case(seed, kind)
    assert np.array_equal(own.u, default.u) and np.array_equal(own.y, default.y)
    with pytest.raises(ValueError, match="excitations"):
        generate_case(seed, kind, excitations="other")


@pytest.mark.parametrize("name", ["decay", "staircase", "trapezoid", "multisine", "bursts"])
def test_each_alternative_excitation_has_its_shape(name):
    from hyst_sim.generator.excitation_alt import excitation_alt
    t = np.arange(16000) / 2000.0
    u = excitation_alt(name, t, 0.0, 150.0, np.random.default_rng(3), np.random.default_rng(4))
    assert u.min() >= 0.0 and u.max() <= 150.0 and np.ptp(u[t > 0.2]) > 0.1 * 150.0
    du = np.abs(np.diff(u[t > 0.25]))
    still = np.mean(du < 1e-12)
    if name == "staircase":        # holds between jumps, up and down
        assert still > 0.95 and np.sum(du > 1.0) >= 8
    elif name == "trapezoid":      # ramps and holds, no jumps
        assert 0.1 < still < 0.9 and du.max() < 150.0 * 0.5e-3 / 0.05 * 2.1
    elif name == "bursts":         # rests at one level between bursts
        assert still > 0.1 and du.max() < 0.1 * 150.0
    else:                          # always moving
        assert still < 0.01
    with pytest.raises(ValueError, match="excitation kind"):
        excitation_alt("square", t, 0.0, 150.0, np.random.default_rng(3), np.random.default_rng(4))


@pytest.mark.parametrize("name", ["decay", "staircase", "trapezoid", "multisine", "bursts"])
def test_alternative_excitations_end_on_a_coarse_sampling_and_refuse_a_record_too_short(name):
    from hyst_sim.generator.excitation_alt import excitation_alt
    t = np.arange(40) * 5.0                     # one sample every 5 s: holds and bursts shorter than a sample
    u = excitation_alt(name, t, -5.0, 5.0, np.random.default_rng(1), np.random.default_rng(2))
    assert u.shape == t.shape and np.all((-5.0 <= u) & (u <= 5.0))
    for short in (np.arange(1) * 1e-3, np.arange(500) * 1e-3):
        with pytest.raises(ValueError, match="at least 2 samples over at least 1 s"):
            excitation_alt(name, short, -5.0, 5.0, np.random.default_rng(1), np.random.default_rng(2))
