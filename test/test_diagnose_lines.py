"""Lines in the output the input does not drive (mains pickup): found, kept out of the effects, counted in the floor."""
from __future__ import annotations

import numpy as np
import pytest

from hyst_model.diagnose.lines import MIN_SHARE, Line, disturbance_lines, floor_with_lines

RATE, N = 2000.0, 16000
T = np.arange(N) / RATE
SIGMA = 2e-9


def _steps(rng: np.random.Generator) -> np.ndarray:
    """Steps with holds of random length (a regular step period puts lines at its harmonics, 50 Hz among them)."""
    holds = rng.integers(int(0.4 * RATE), int(1.5 * RATE), N // int(0.4 * RATE) + 1)
    return np.repeat(rng.uniform(0.0, 150.0, holds.size), holds)[:N]


def _noise_input(rng: np.random.Generator) -> np.ndarray:
    from scipy.signal import butter, sosfiltfilt
    return 75.0 + 60.0 * sosfiltfilt(butter(4, 10.0, fs=RATE, output="sos"), rng.standard_normal(N)) * 8


@pytest.mark.parametrize("seed", range(6))
def test_white_noise_has_no_line(seed):
    rng = np.random.default_rng(seed)
    for u in (_steps(rng), _noise_input(rng), 75 + 70 * np.sin(2 * np.pi * 3.3 * T)):
        assert disturbance_lines(T, u, SIGMA * rng.standard_normal(N), SIGMA) == []


@pytest.mark.parametrize("seed", range(4))
def test_mains_and_its_harmonic_found(seed):
    rng = np.random.default_rng(100 + seed)
    f = 50.0 * rng.uniform(0.998, 1.002)
    e = (SIGMA * rng.standard_normal(N) + 2.5 * SIGMA * np.sin(2 * np.pi * f * T + rng.uniform(0, 6.3))
         + 1.2 * SIGMA * np.sin(6 * np.pi * f * T + rng.uniform(0, 6.3)))
    lines = disturbance_lines(T, _steps(rng), e, SIGMA)
    assert len(lines) == 2
    assert abs(lines[0].frequency - f) < 0.02 and abs(lines[1].frequency - 3 * f) < 0.05
    assert lines[0].amplitude == pytest.approx(2.5 * SIGMA, rel=0.1)
    assert lines[1].amplitude == pytest.approx(1.2 * SIGMA, rel=0.15)
    assert floor_with_lines(SIGMA, lines) == pytest.approx(SIGMA * np.sqrt(1 + 2.5 ** 2 / 2 + 1.2 ** 2 / 2), rel=0.1)


def test_harmonics_and_intermodulation_of_the_input_are_not_disturbances():
    """A model error driven by the input answers at the input's harmonics and their sums and differences: by
    frequency those cannot be told from pickup, so they are left to the model (a dead zone on two sines)."""
    rng = np.random.default_rng(7)
    u = 75 + 40 * np.sin(2 * np.pi * 4.482 * T) + 30 * np.sin(2 * np.pi * 10.2132 * T + 1.0)
    dz = np.where(np.abs(u - 75) < 12, 75.0, u - np.sign(u - 75) * 12)
    e = 40e-9 * (dz - u) / 12 + SIGMA * rng.standard_normal(N)
    assert disturbance_lines(T, u, e, SIGMA) == []
    u1 = 75 + 70 * np.sin(2 * np.pi * 7.0 * T)   # one sine: every harmonic of it
    e1 = 30e-9 * ((u1 - 75) / 70) ** 3 + 20e-9 * np.abs((u1 - 75) / 70) + SIGMA * rng.standard_normal(N)
    assert disturbance_lines(T, u1, e1, SIGMA) == []


def test_a_line_that_comes_and_goes_is_not_a_disturbance():
    rng = np.random.default_rng(8)
    e = SIGMA * rng.standard_normal(N) + np.where(T > T[-1] / 2, 3 * SIGMA, 0.0) * np.sin(2 * np.pi * 50 * T)
    assert disturbance_lines(T, _steps(rng), e, SIGMA) == []


def test_a_line_too_small_to_matter_is_not_reported():
    rng = np.random.default_rng(9)
    amp = 0.6 * MIN_SHARE * SIGMA * np.sqrt(2)           # RMS 0.6 × the share that counts
    e = SIGMA * rng.standard_normal(N) + amp * np.sin(2 * np.pi * 50 * T)
    assert disturbance_lines(T, _steps(rng), e, SIGMA) == []


def test_slow_trend_is_not_a_line():
    rng = np.random.default_rng(10)
    e = SIGMA * rng.standard_normal(N) + 40 * SIGMA * T / T[-1] + 10 * SIGMA * np.sin(2 * np.pi * 0.5 * T)
    assert disturbance_lines(T, _steps(rng), e, SIGMA) == []


def test_line_json_in_si():
    ln = Line(50.0, 3e-9, 1e4)
    assert ln.to_json() == {"frequency": 50.0, "amplitude": 3e-9, "rms": 3e-9 / np.sqrt(2), "ratio": 1e4, "phase": 0.0}
    assert ln.signal(np.array([0.0, 0.01]))[0] == pytest.approx(3e-9)


def test_generator_sensor_option():
    from hyst_sim.generator import SENSORS, generate_case
    assert SENSORS == ("white", "hum", "coloured", "quantised")
    a, w = generate_case(11, "none"), generate_case(11, "none", sensor="white")
    assert np.array_equal(a.y, w.y) and np.array_equal(a.y_fresh, w.y_fresh)   # the white families unchanged
    for kind in ("hum", "coloured"):
        b = generate_case(11, "none", sensor=kind)
        assert np.array_equal(a.u, b.u)
        extra, extra_f = b.y - a.y, b.y_fresh - a.y_fresh
        assert 0.7 * a.noise < np.std(extra) < 4 * a.noise and 0.7 * a.noise < np.std(extra_f) < 4 * a.noise
        assert np.std(extra - extra_f) > 0.5 * a.noise   # the fresh record: a new phase or realisation
    with pytest.raises(ValueError, match="sensor must be one of"):
        generate_case(11, "none", sensor="pink")


@pytest.mark.slow
def test_stage_with_mains_pickup_is_complete_and_says_why():
    """Generated PEA stage with no effect and a 60 Hz pickup 3.5× the white noise on steps: was ``unexplained``
    (2.7× the white floor); the line is found, taken out before fitting, and the answer is ``none`` with the line."""
    from hyst_model.diagnose.diagnose import diagnose
    from hyst_sim.generator import generate_case
    c = generate_case(3, "none", sensor="hum")
    d = diagnose(c.t, c.u, c.y)
    assert d.missing == "none" and d.n_removed >= 1
    j = d.to_json()
    assert abs(j["disturbances"][0]["frequency"] - 60.0) < 0.2 and j["disturbances"][0]["removed"]
    assert j["noise_floor"] == pytest.approx(c.noise, rel=0.1)        # the white floor: the line is gone
    assert "59.96 Hz" in d.explanation and "taken out of the record" in d.explanation
    y = d.record_fitted(c.t, c.y)
    w = generate_case(3, "none")                                      # the same stage and noise, no pickup
    assert np.std(y - w.y) < 0.5 * c.noise < 2 * c.noise < np.std(c.y - w.y)   # (a third harmonic < 0.5σ left)
    dw = diagnose(w.t, w.u, w.y)
    assert dw.missing == "none" and dw.disturbances == [] and dw.noise_white == dw.noise
    assert np.array_equal(dw.record_fitted(w.t, w.y), w.y)


@pytest.mark.slow
def test_mode_does_not_ring_at_the_pickup():
    """Generated GMA stage with no effect, 60 Hz pickup on band-limited noise: a lightly damped mode rang at the
    line and was named ``dynamics`` (the input's noise band had passed for lines whose products covered 60 Hz)."""
    from hyst_model.diagnose.diagnose import diagnose
    from hyst_sim.generator import generate_case
    c = generate_case(6500021, "none", sensor="hum")
    d = diagnose(c.t, c.u, c.y)
    assert d.missing == "none" and d.n_removed == 1


@pytest.mark.slow
def test_fit_and_diagnose_take_the_same_line_out(tmp_path):
    """One path: ``hyst fit`` takes the line out as ``hyst diagnose`` does, and both write the same base model."""
    import json
    import subprocess
    import sys

    import yaml
    from hyst_sim.generator import generate_case
    c = generate_case(3, "none", sensor="hum")
    data = tmp_path / "rec.csv"
    np.savetxt(data, np.column_stack([c.t, c.u, c.y]), delimiter=",", header="t,u,y", comments="")
    cmd = [sys.executable, "-c", "import sys; from hyst_model.cli.main import main; sys.exit(main())"]
    fit = subprocess.run(cmd + ["fit", str(data), "--out", str(tmp_path / "f.yaml"), "--json"],
                         capture_output=True, text=True, timeout=600)
    assert fit.returncode == 0, fit.stderr
    fj = json.loads(fit.stdout)
    assert abs(fj["disturbances"][0]["frequency"] - 59.96) < 0.01 and fj["disturbances"][0]["removed"]
    assert fj["method"] == "fast (refitted without the lines)" and "59.96 Hz" in fj["data_notes"][0]
    dg = subprocess.run(cmd + ["diagnose", str(data), "--out", str(tmp_path / "d.yaml"), "--json"],
                        capture_output=True, text=True, timeout=600)
    assert dg.returncode == 0, dg.stderr
    dj = json.loads(dg.stdout)
    assert dj["disturbances"][0]["removed"] and "59.96 Hz" in dj["data_notes"][0]
    f = yaml.safe_load((tmp_path / "f.yaml").read_text())["/**"]["ros__parameters"]
    g = yaml.safe_load((tmp_path / "d.yaml").read_text())["/**"]["ros__parameters"]
    assert f["model"] == g["model"]
    assert "taken out of the output before fitting" in f["fit"]["data_notes"]
    assert "taken out of the output before fitting" in g["fit"]["data_notes"]


def test_compare_names_pickup_not_a_resonance():
    """``hyst compare``'s figures: a mains line in the residual is named as pickup, not listed as a resonance."""
    from hyst_model.diagnose.report import findings
    from hyst_model.diagnose.stats import compare_stats
    rng = np.random.default_rng(12)
    u = _steps(rng)
    yhat = 1e-7 * u
    y = yhat + SIGMA * rng.standard_normal(N) + 4 * SIGMA * np.sin(2 * np.pi * 50.0 * T + 0.3)
    st = compare_stats(T, u, y, yhat)
    lines = st.to_dict()["disturbances"]
    assert len(lines) == 1 and abs(lines[0]["frequency"] - 50.0) < 0.02
    said = " ".join(findings(st))
    assert "mains pickup" in said and "50 Hz" in said
    assert any(abs(p["freq"] - 50.0) <= 1.0 for p in st.extra["peaks"])      # the spectrum's peak is there ...
    assert not any("resonances" in f and "50 Hz" in f for f in findings(st))  # ... but not called a resonance
    clean = compare_stats(T, u, yhat + SIGMA * rng.standard_normal(N), yhat)
    assert clean.to_dict()["disturbances"] == [] and "mains" not in " ".join(findings(clean))


def test_periodic_input_is_not_refined_harmonic_by_harmonic():
    """A triangle's hundreds of harmonics: only the few lines used are refined (each refinement is some 16 fits
    over the record; all of them took 46 s on a loaded machine). Counted, not timed."""
    import hyst_model.diagnose.lines as L
    calls = []
    orig = L._refine

    def counting(*a):
        calls.append(1)
        return orig(*a)
    rng = np.random.default_rng(13)
    ph = (1.0 * T) % 1.0
    u = 75 + 70 * (2 * np.abs(2 * ph - 1) - 1)
    e = SIGMA * rng.standard_normal(N) + 3 * SIGMA * np.sin(2 * np.pi * 50.37 * T)
    L._refine = counting
    try:
        L.disturbance_lines(T, u, e, SIGMA)
    finally:
        L._refine = orig
    assert len(calls) <= 6 + 3 * L.MAX_LINES


def test_a_bench_sensors_harmonics_are_taken_and_a_longer_list_says_where_the_search_stops():
    """Mains pickup through a rectifier: the mains and seven harmonics are all found (a cap of four left half of
    them in the floor); with ten lines the search stops at MAX_LINES and the words say so."""
    from hyst_model.diagnose.lines import MAX_LINES, said
    rng = np.random.default_rng(31)
    f = 50.0 * rng.uniform(0.998, 1.002)
    u = _steps(rng)
    base = SIGMA * rng.standard_normal(N)

    def hum(k: int) -> np.ndarray:
        return sum((3.0 - 0.15 * i) * SIGMA * np.sin(2 * np.pi * (i + 1) * f * T + rng.uniform(0, 6.3))
                   for i in range(k))
    eight = disturbance_lines(T, u, base + hum(8), SIGMA)
    assert sorted(round(ln.frequency / f) for ln in eight) == list(range(1, 9))
    assert "the search stops" not in said(eight[:MAX_LINES - 1])
    ten = disturbance_lines(T, u, base + hum(10), SIGMA)
    assert len(ten) == MAX_LINES
    assert "the search stops at 8 lines" in said(ten)
