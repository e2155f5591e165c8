"""A reading quantised in steps not fine against its noise: the floor is its error, read by local fits."""
from __future__ import annotations

import numpy as np
import pytest

from hyst_model.effects.quantised import lattice_step, local_noise, quantised_floor
from hyst_model.effects.signals import noise_floor, record_floor

RATE, N = 2000.0, 16000
T = np.arange(N) / RATE


def _triangle(amplitude: float = 10e-6, f: float = 1.0) -> np.ndarray:
    """A stage's smooth course: a triangle of ``amplitude`` (m) at ``f`` (Hz) about 15 µm."""
    return 15e-6 + amplitude * (2.0 * np.abs(2.0 * ((T * f) % 1.0) - 1.0) - 1.0)


def _sine(amplitude: float = 10e-6, f: float = 0.5) -> np.ndarray:
    """A stage's smooth course at every speed from rest to ``2π f amplitude`` (no speed commensurate with a step,
    where the quantisation error would be a constant an offset takes)."""
    return 15e-6 + amplitude * np.sin(2.0 * np.pi * f * T)


def _read(x: np.ndarray, q: float, sigma: float, seed: int = 0, zero: float = 0.37) -> np.ndarray:
    """A digital sensor: white noise ``sigma``, then rounded to steps of ``q`` about a zero of ``zero`` q."""
    rng = np.random.default_rng(seed)
    return zero * q + q * np.round((x + sigma * rng.standard_normal(x.size) - zero * q) / q)


def _rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e ** 2)))


def test_lattice_step_is_found_and_only_where_there_is_one():
    x = _triangle()
    y = _read(x, 5e-9, 1e-9)
    assert lattice_step(y) == pytest.approx(5e-9, rel=1e-6)
    assert lattice_step(x + 1e-9 * np.random.default_rng(1).standard_normal(N)) == 0.0    # floats: none
    glitch = y.copy()
    glitch[[100, 5000]] += 1.3e-9                                                         # two off the lattice
    assert lattice_step(glitch) == 0.0 or lattice_step(glitch) == pytest.approx(5e-9, rel=1e-6)
    assert lattice_step(np.full(N, 1e-6)) == 0.0 and lattice_step(np.array([0.0, 1.0])) == 0.0


@pytest.mark.parametrize("seed", range(3))
def test_local_noise_reads_white_noise_on_a_moving_stage(seed):
    sigma = 2e-9
    rng = np.random.default_rng(seed)
    assert local_noise(_triangle() + sigma * rng.standard_normal(N)) == pytest.approx(sigma, rel=0.05)
    assert local_noise(np.ones(5)) == 0.0


@pytest.mark.parametrize("ratio", [3.0, 5.0, 10.0])
def test_coarse_steps_give_the_error_of_the_reading_where_differences_misread_it(ratio):
    """q = 3–10 σ on a slow sine: the reading's error (quantisation with noise) is what an exact model leaves.
    Second differences overstate it (flips at the thresholds, anti-correlated); the local fits read it."""
    sigma = 1e-9
    q = ratio * sigma
    x = _sine()
    y = _read(x, q, sigma)
    true = _rms(y - x)
    floor, step = quantised_floor(y, y - x)
    assert step == pytest.approx(q, rel=1e-6)
    assert floor == pytest.approx(true, rel=0.1)
    assert record_floor(y, y - x) == floor
    assert abs(min(noise_floor(y), noise_floor(y - x)) / true - 1.0) > 0.12   # what second differences said


def test_a_staircase_keeps_the_quantisation_error_as_its_floor():
    """Steps held still, σ ≪ q: most changes of the reading are exactly zero, so the median of the second
    differences is 0 and their fallback reads the record's steps or too little; the floor is the error an exact
    model leaves, at least q/√12."""
    q = 8e-9
    levels = np.repeat(np.random.default_rng(3).uniform(2e-6, 28e-6, 16), N // 16)
    y = _read(levels, q, 0.05 * q)
    true = _rms(y - levels)
    floor, step = quantised_floor(y, y - levels)
    assert step == pytest.approx(q, rel=1e-6)
    assert floor >= 0.999 * q / np.sqrt(12.0) and floor == pytest.approx(true, rel=0.1)
    assert noise_floor(y) > 10 * true and noise_floor(y - levels) < 0.8 * true   # the differences' answers


def test_fine_steps_keep_the_second_differences_bit_for_bit():
    """An error of ≥ 3 steps (2 nm noise on 0.2 nm steps, or float resolution): the second differences' median
    moves by half steps, a small share of it — they read it, and nothing changes."""
    x = _triangle()
    for q in (0.2e-9, 1e-12):
        y = _read(x, q, 2e-9)
        assert quantised_floor(y, y - x) == (0.0, 0.0)
        assert record_floor(y, y - x) == min(noise_floor(y), noise_floor(y - x))


@pytest.mark.parametrize("ratio", [0.6, 0.8, 1.0, 1.5])
def test_steps_as_large_as_the_noise_are_read_by_local_fits(ratio):
    """σ = 0.6–1.5 q (the simulated stage: 2 nm noise, 2 nm steps): the quantisation error is white, but the
    second differences of a reading on a lattice are whole steps, and their median moves in half steps (the floor
    off by up to 30 % here); the local fits read the error."""
    q = 2e-9
    x = _sine()
    y = _read(x, q, ratio * q, seed=5)
    floor, step = quantised_floor(y, y - x)
    assert step == pytest.approx(q, rel=1e-6)
    assert floor == pytest.approx(_rms(y - x), rel=0.05)


def test_compare_says_the_steps_and_judges_the_residual_against_their_error():
    """``hyst compare`` on the exact model of a stage moving slowly (1 µm at 0.2 Hz) read in 10 nm steps with 1 nm
    noise: the residual is at the sensor noise level, which is the reading's error — the third differences of a
    reading that mostly stays on one step said 0."""
    from hyst_model.diagnose.figures import noise_sigma
    from hyst_model.diagnose.report import findings
    from hyst_model.diagnose.stats import compare_stats
    x = _sine(1e-6, 0.2)
    u = 75.0 + 5.0 * np.sin(2.0 * np.pi * 0.2 * T)
    y = _read(x, 10e-9, 1e-9, seed=4)
    st = compare_stats(T, u, y, x)
    said = " ".join(findings(st))
    assert st.to_dict()["noise_step"] == pytest.approx(10e-9, rel=1e-6)
    assert st.noise_sigma == pytest.approx(_rms(y - x), rel=0.1)
    assert noise_sigma(y) < 0.5 * _rms(y - x)                      # what the differences said
    assert "steps of 10 nm" in said and "at the sensor noise level" in said
    from hyst_model.cli.compare import summary_text
    assert "read in steps of 10 nm" in summary_text(st)
    fine = compare_stats(T, u, _read(x, 0.1e-9, 1e-9, seed=4), x)
    assert fine.to_dict()["noise_step"] is None and "steps of" not in " ".join(findings(fine))


@pytest.mark.slow
def test_complete_stage_read_in_coarse_steps_is_not_unexplained():
    """Generated PEA stage with no effect on triangles, read in 4.2 nm steps with 0.8 nm noise (6800070): the
    second differences' median was 0 and the floor vanished, so the exact base was ``unexplained``; the floor is
    now the reading's error (1.3 nm by construction) and the answer ``none``, saying why."""
    from hyst_model.diagnose.diagnose import diagnose
    from hyst_sim.generator import generate_case
    c = generate_case(6800070, "none", sensor="quantised")
    d = diagnose(c.t, c.u, c.y)
    assert d.missing == "none" and d.unexplained is None
    assert d.noise == pytest.approx(c.noise, rel=0.15)
    assert d.noise_step == pytest.approx(lattice_step(c.y), rel=1e-9) and d.noise_step > 2.5 * c.noise
    assert "steps of" in d.explanation and d.to_json()["noise_floor_step"] == d.noise_step
    w = diagnose(c.t, c.u, generate_case(6800070, "none").y)   # the same stage, white noise: nothing said
    assert w.missing == "none" and w.noise_step is None and "steps of" not in w.explanation


def test_generator_quantised_sensor():
    """The generator's quantised sensor: both records on one lattice of 2–10× its white part, the reading's error
    the white family's RMS (the sizes mean the same), the stage and its input those of the white family."""
    from hyst_sim.generator import generate_case
    import hyst_sim.generator.cases as cases
    seen = {}
    read = cases._read

    def spy(kind, seed, t, clean, white, noise, record):
        seen[record] = clean
        return read(kind, seed, t, clean, white, noise, record)

    cases._read = spy
    try:
        c = generate_case(11, "none", sensor="quantised")
    finally:
        cases._read = read
    w = generate_case(11, "none")
    assert np.array_equal(c.u, w.u)
    q = lattice_step(c.y)
    assert q > 0 and lattice_step(c.y_fresh) == pytest.approx(q, rel=1e-6)
    # q = r σ' with σ'² + q²/12 = noise²: q/noise = r / √(1 + r²/12), 1.73 to 3.27 for r in 2–10
    assert 1.73 * c.noise < q < 3.27 * c.noise
    assert _rms(c.y - seen[0]) == pytest.approx(c.noise, rel=0.1)
    assert not np.array_equal(c.y - seen[0], c.y_fresh - seen[1])


def test_lines_are_out_of_the_floor_of_a_reading_in_coarse_steps():
    """A 150 Hz line on a reading in 5 nm steps (0.7 nm noise, 1 kHz): local fits read much of a line, so the floor
    is read on the reading without the lines found — not with their power (1.43× too high), and not by second
    differences where the line pushed the local reading past the coarse limit (3 nm: step lost)."""
    from hyst_model.diagnose.stats import compare_stats
    rate = 1000.0
    t = np.arange(8000) / rate
    x = 15e-6 + 10e-6 * np.sin(2 * np.pi * 0.37 * t)
    u = 75.0 + 60.0 * np.sin(2 * np.pi * 0.37 * t)
    rng = np.random.default_rng(2)
    q, sigma = 5e-9, 0.7e-9
    white = sigma * rng.standard_normal(t.size)
    clean = 0.37 * q + q * np.round((x + white - 0.37 * q) / q)
    true = _rms(clean - x)
    for amp in (2e-9, 3e-9):
        y = 0.37 * q + q * np.round((x + amp * np.sin(2 * np.pi * 150.0 * t + 0.3) + white - 0.37 * q) / q)
        st = compare_stats(t, u, y, x)
        assert st.extra["disturbances"] and st.extra["noise_step"] == pytest.approx(q, rel=1e-6)
        assert st.noise_sigma == pytest.approx(true, rel=0.15)


def test_a_noiseless_ramp_and_a_short_record_are_not_a_quantiser():
    """Every change alike is a noiseless record at constant speed, not a reading in steps; a record shorter than
    one run of local fits gives no reading (the floor stays the second differences')."""
    line = 1e-6 + 20e-9 * np.arange(N)                       # a simulated ramp, 20 nm a sample, no noise
    assert lattice_step(line) == 0.0
    assert quantised_floor(line, np.zeros(N)) == (0.0, 0.0)
    assert record_floor(line, np.zeros(N)) < 1e-12
    short = np.round(np.random.default_rng(0).normal(0.0, 5.0, 11)) * 1e-9
    assert quantised_floor(short, short) == (0.0, 0.0)


@pytest.mark.slow
def test_diagnose_reads_the_coarse_floor_without_the_lines_it_takes_out():
    from hyst_model.diagnose.diagnose import diagnose
    rate = 1000.0
    t = np.arange(8000) / rate
    u = 75.0 + 60.0 * np.sin(2 * np.pi * 0.37 * t)
    x = 15e-6 + 10e-6 * np.sin(2 * np.pi * 0.37 * t)
    rng = np.random.default_rng(2)
    q, white = 5e-9, 0.7e-9 * rng.standard_normal(t.size)
    true = _rms(0.37 * q + q * np.round((x + white - 0.37 * q) / q) - x)
    y = 0.37 * q + q * np.round((x + 2e-9 * np.sin(2 * np.pi * 150.0 * t + 0.3) + white - 0.37 * q) / q)
    d = diagnose(t, u, y, effects=["drift"], jobs=1)
    assert d.n_removed >= 1 and d.noise_step == pytest.approx(q, rel=1e-6)
    assert d.noise_white == pytest.approx(true, rel=0.15)
