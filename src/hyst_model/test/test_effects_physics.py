"""Each effect against known answers: creep linear in log time, exact delays, drift trend, soft limit, even term;
and each effect's start() recovers a planted effect from a residual."""
import numpy as np
import pytest

from hyst_model.effects.base import Inner
from hyst_model.effects.creep import Creep, creep_term
from hyst_model.effects.delay import Delay
from hyst_model.effects.drift import Drift
from hyst_model.effects.saturation import Saturation, soft_limit
from hyst_model.effects.asymmetry import Asymmetry
from hyst_model.effects.signals import holds, noise_floor

CFG = {"u_scale": 15.0, "y_scale": 5.42e-6, "dt": 1e-3}


class _Lin:
    """Identity base: y = 1e-7 m/V · u (so effects can be checked in isolation)."""
    name = "lin"

    def params(self):
        return ()

    def config(self):
        return {}

    def simulate(self, theta, t, u):
        return 1e-7 * np.asarray(u, float)


def _apply(effect, theta, t, u):
    b = _Lin()
    return effect.apply(np.asarray(theta, float), t, u, Inner(lambda tt, uu: b.simulate((), tt, uu), b, np.empty(0)))


def test_creep_after_a_step_grows_linearly_in_log_time_and_settles_to_the_static_map():
    dt = 1e-3
    t = np.arange(int(400 / dt)) * dt
    u = np.where(t >= 1.0, 100.0, 0.0)
    y = _apply(Creep(CFG), [0.02, 0.0], t, u)
    x = 1e-7 * u
    step = 1e-5
    # per decade of time after the step the output gains gain·Δ = 2 % of the step (0.1 s … 10 s window)
    def at(s):
        return y[int((1.0 + s) / dt)]
    d1, d2 = at(1.0) - at(0.1), at(10.0) - at(1.0)
    assert d1 == pytest.approx(0.02 * step, rel=0.15) and d2 == pytest.approx(0.02 * step, rel=0.15)
    assert y[-1] == pytest.approx(x[-1], rel=5e-3)           # long hold: back to the base model's static map
    assert y[int(1.0 / dt)] < x[int(1.0 / dt)] - 0.05 * step  # right after the step it falls short


def test_creep_term_zero_at_rest():
    t = np.arange(1000) * 1e-3
    assert np.all(creep_term(t, np.full(1000, 3.0)) == 0.0)


@pytest.mark.parametrize("k", [1, 3, 7])
def test_delay_by_whole_samples_is_an_exact_shift(k):
    t = np.arange(500) * 1e-3
    u = np.sin(2 * np.pi * 3 * t) * 50 + 75
    y = _apply(Delay(CFG), [k * 1e-3], t, u)
    np.testing.assert_allclose(y[k:], 1e-7 * u[:-k], rtol=1e-12)
    np.testing.assert_allclose(y[:k], 1e-7 * u[0])


def test_drift_is_zero_at_start_follows_knots_and_extrapolates_the_trend():
    d = Drift(dict(CFG, **{"drift.knots": 4, "drift.span": 8.0}))
    t = np.arange(0, 12, 0.01)
    u = np.zeros_like(t)
    y = _apply(d, [1e-8, 2e-8, 3e-8, 4e-8], t, u)  # a straight line of 5e-9 m/s
    np.testing.assert_allclose(y, 5e-9 * t, atol=1e-20)



def test_drift_early_spacing_puts_the_knots_at_the_square_of_even_ones_and_old_files_read_even():
    """``drift.spacing: early`` places knot j at span·(j/K)², so a warm-up that settles in the first second of an
    8 s record is followed; a configuration without the key (params files before it) is the even spacing."""
    from hyst_model.errors import EffectError
    t = np.arange(0, 8, 0.01)
    u = np.zeros_like(t)
    early = Drift(dict(CFG, **{"drift.knots": 4, "drift.span": 8.0, "drift.spacing": "early"}))
    y = _apply(early, [1e-8, 2e-8, 3e-8, 4e-8], t, u)
    for j, c in enumerate([1e-8, 2e-8, 3e-8, 4e-8], start=1):
        k = int(round(8.0 * (j / 4) ** 2 / 0.01))
        assert y[min(k, t.size - 1)] == pytest.approx(c if k < t.size else 3e-8 + (t[-1] - 4.5) / 3.5 * 1e-8)
    warm = 3e-8 * (1 - np.exp(-t / 0.3))
    fits = {}
    for sp in ("even", "early"):
        d = Drift(dict(CFG, **{"drift.knots": 5, "drift.span": 8.0, "drift.spacing": sp}))
        st = d.start(t, u, warm, warm)
        fits[sp] = np.sqrt(np.mean((warm - _apply(d, [st[f"c{j}"] for j in range(1, 6)], t, u)) ** 2))
    assert fits["early"] < 0.5 * fits["even"]
    assert Drift(dict(CFG, **{"drift.knots": 4})).spacing == "even"
    with pytest.raises(EffectError):
        Drift(dict(CFG, **{"drift.spacing": "late"}))


def test_saturation_soft_limit_is_identity_inside_and_bounded_outside():
    x = np.linspace(-2, 2, 401)
    y = soft_limit(x, top=1.0, bottom=-1.0, w=0.2, two_sided=True)
    inside = np.abs(x) <= 0.8
    np.testing.assert_array_equal(y[inside], x[inside])
    assert y.max() < 1.0 and y.min() > -1.0 and np.all(np.diff(y) > 0)
    y1 = soft_limit(x, top=1.0, bottom=-1.0, w=0.2, two_sided=False)
    np.testing.assert_array_equal(y1[x < 0], x[x < 0])


def test_asymmetry_output_term_is_even_about_the_centre():
    a = Asymmetry(dict(CFG, **{"asymmetry.u_c": 0.0, "asymmetry.y_c": 0.0}))
    t = np.arange(200) * 1e-3
    u = np.linspace(-50, 50, 200)
    y = _apply(a, [0.0, 0.1], t, u) - 1e-7 * u
    np.testing.assert_allclose(y, y[::-1], rtol=1e-9)
    assert np.all(y >= 0) and y[0] > 0


def _residual_of(effect, theta, t, u):
    return _apply(effect, theta, t, u) - 1e-7 * u


def test_starts_recover_planted_effects():
    dt = 1e-3
    t = np.arange(int(20 / dt)) * dt
    u = np.repeat([0, 80, 20, 140, 60], t.size // 5).astype(float)
    y_lin = 1e-7 * u
    # creep
    r = _residual_of(Creep(CFG), [0.03, 0.0], t, u)
    assert Creep(CFG).start(t, u, y_lin + r, r)["gain"] == pytest.approx(0.03, rel=0.1)
    # delay (a sine so that the shift shows)
    us = 75 + 60 * np.sin(2 * np.pi * 1.5 * t)
    r = _residual_of(Delay(CFG), [0.004], t, us)
    assert Delay(CFG).start(t, us, 1e-7 * us + r, r)["tau"] == pytest.approx(0.004, abs=1e-3)
    # drift
    d = Drift(dict(CFG, **{"drift.knots": 4}))
    r = _residual_of(d, [2e-8, 1e-8, -1e-8, 3e-8], t, u)
    st = d.start(t, u, y_lin + r, r)
    np.testing.assert_allclose([st[f"c{j}"] for j in range(1, 5)], [2e-8, 1e-8, -1e-8, 3e-8], atol=1e-12)
    # saturation: the start finds a limit below the largest excursion
    s = Saturation(CFG)
    r = _residual_of(s, [1.3e-5, -1.0, 1e-6], t, u)
    st = s.start(t, u, y_lin + r, r)
    assert st and st["top"] < 1.45e-5


def test_signatures_point_at_their_own_effect():
    dt = 1e-3
    t = np.arange(int(30 / dt)) * dt
    u = np.repeat([0, 80, 20, 140, 60, 100], t.size // 6).astype(float)
    r_creep = _residual_of(Creep(CFG), [0.03, 0.0], t, u)
    s_creep, ev = Creep(CFG).signature(t, u, r_creep, dt)
    assert s_creep > 0.8 and "log time" in ev
    s_drift, _ = Drift(CFG).signature(t, u, r_creep, dt)
    assert s_drift < s_creep
    us = 75 + 60 * np.sin(2 * np.pi * 1.5 * t)
    r_delay = _residual_of(Delay(CFG), [0.003], t, us)
    s_delay, _ = Delay(CFG).signature(t, us, r_delay, dt)
    assert s_delay > 0.9
    s_creep2, _ = Creep(CFG).signature(t, us, r_delay, dt)
    assert s_creep2 < 0.1


def test_helpers_holds_and_noise_floor():
    dt = 1e-3
    u = np.repeat([0.0, 50.0, 20.0], 1000)
    hs = holds(u, dt, min_seconds=0.5)
    assert [(a, b) for a, b, _ in hs] == [(0, 1000), (1000, 2000), (2000, 3000)]
    assert [s for *_, s in hs] == [0.0, 50.0, -30.0]
    rng = np.random.default_rng(3)
    y = 1e-6 * np.sin(np.arange(50000) * 2e-3) + rng.normal(0, 2e-9, 50000)
    assert noise_floor(y) == pytest.approx(2e-9, rel=0.05)


def test_compose_with_config_keys_round_trips():
    from hyst_model.spec import build_model
    m = build_model("mbw", ["drift", "saturation", "asymmetry"], dict(CFG, **{"drift.knots": 3}))
    cfg = m.config()
    assert cfg["drift.knots"] == 3 and "saturation.two_sided" in cfg and "asymmetry.u_c" in cfg
    m2 = build_model("mbw", ["drift", "saturation", "asymmetry"], cfg)
    assert m2.names == m.names


def test_asymmetry_kink_bends_the_gain_at_one_level_its_start_finds_it_and_the_inverse_undoes_it():
    """``asymmetry.form: kink``: the gain changes by ``slope`` above ``level`` (soft over 2 % of the range); the
    data-driven start recovers a planted kink; the controllers' inverse is exact; a quadratic file is unchanged."""
    from hyst_model.effects.asymmetry import Asymmetry
    from hyst_model.errors import EffectError
    cfg = dict(CFG, **{"asymmetry.form": "kink", "asymmetry.y_lo": 0.0, "asymmetry.y_hi": 1.5e-5})
    a = Asymmetry(cfg)
    assert [p.name for p in a.params()] == ["slope", "level"]
    t = np.arange(0, 4, 1e-3)
    u = 75 + 75 * np.sin(2 * np.pi * 0.5 * t)            # x = 1e-7·u spans 0 … 15 µm
    y = _apply(a, [-0.2, 1.0e-5], t, u)
    x = 1e-7 * u
    lo, hi = x < 0.8e-5, x > 1.2e-5                                              # 6.7 widths from the level
    np.testing.assert_allclose(y[lo], x[lo], rtol=0, atol=1e-10)                 # identity below the level
    np.testing.assert_allclose(y[hi], x[hi] - 0.2 * (x[hi] - 1e-5), rtol=0, atol=1e-10)  # 20 % less gain above
    st = a.start(t, u, y, y - x)
    assert st["level"] == pytest.approx(1.0e-5, abs=1.5e-6) and st["slope"] == pytest.approx(-0.2, abs=0.05)
    inv = a.online(np.array([-0.2, 1.0e-5]))
    back = np.array([inv.measure(float(v), 0.0) for v in y])
    np.testing.assert_allclose(back, x, atol=1e-15)
    # a file without the key reads as the quadratic, and files now say so (a node declares the key with a default)
    assert Asymmetry(CFG).form == "quadratic" and Asymmetry(CFG).config()["form"] == "quadratic"
    assert Asymmetry(CFG).form == "quadratic"
    with pytest.raises(EffectError):
        Asymmetry(dict(CFG, **{"asymmetry.form": "cubic"}))
