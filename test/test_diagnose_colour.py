"""Sensor noise that is not white: read where the input is held still, and the floor when larger than the white."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from hyst_model.diagnose.colour import MARGIN, hold_noise, still_spans
from hyst_model.effects.signals import noise_floor, record_floor

RATE, N = 2000.0, 16000
T = np.arange(N) / RATE
SIGMA = 2e-9


def _steps(rng: np.random.Generator) -> np.ndarray:
    """The benchmark generator's steps with holds (0.4–1.5 s) over the PEA's 0–150 V."""
    from hyst_sim.generator.excitation import excitation
    return excitation("steps", T, 0.0, 150.0, rng)


def _stage(u: np.ndarray) -> np.ndarray:
    """A stage that does what stages do after a step: it creeps (two lags) and rings (a 300 Hz mode, ζ 0.03)."""
    x = 2e-7 * u
    slow = sum(lfilter([1 - c], [1, -c], 0.05 * x) for c in (np.exp(-1 / (0.05 * RATE)), np.exp(-1 / (0.6 * RATE))))
    w, z = 2 * np.pi * 300.0 / RATE, 0.03
    ring = lfilter([w * w], [1 + 2 * z * w + w * w, -2 - 2 * z * w, 1], np.diff(x, prepend=x[0])) * 0.02
    return x + slow + ring


def _coloured(rng: np.random.Generator, fc: float, level: float) -> np.ndarray:
    c = np.exp(-2 * np.pi * fc / RATE)
    return level * lfilter([np.sqrt(1 - c * c)], [1.0, -c], rng.standard_normal(N))


@pytest.mark.parametrize("seed", range(4))
def test_white_noise_behind_creep_and_ringing_stays_at_the_white_floor(seed):
    rng = np.random.default_rng(seed)
    u = _steps(rng)
    y = _stage(u) + SIGMA * rng.standard_normal(N)
    h = hold_noise(T, u, y)
    assert h is not None and h.holds >= 4
    white = record_floor(y, y - _stage(u))                    # as diagnose judges it (the exact model's residual)
    assert 0.8 * SIGMA < h.rms < MARGIN * white               # not taken: the floor stays the white one


@pytest.mark.parametrize("fc", (20.0, 60.0, 200.0))
def test_low_passed_noise_is_read_in_the_holds(fc):
    """The white floor sees little of noise low-passed well below the sampling; the holds see all but the part
    slower than a hold's quadratic trend."""
    rng = np.random.default_rng(int(fc))
    u = _steps(rng)
    extra = _coloured(rng, fc, 2.0 * SIGMA)
    y = _stage(u) + SIGMA * rng.standard_normal(N) + extra
    total = float(np.sqrt(SIGMA ** 2 + np.mean(extra ** 2)))
    h = hold_noise(T, u, y)
    assert noise_floor(y) < 0.75 * total                      # what the white floor misses ...
    assert h is not None and 0.8 * total < h.rms < 1.1 * total  # ... is read in the holds
    assert h.rms > MARGIN * noise_floor(y)


def test_no_holds_no_reading():
    """Sines, sweeps and a slow noise input hold nothing still (a slow input is not a hold: its output moves)."""
    rng = np.random.default_rng(5)
    from scipy.signal import butter, sosfiltfilt
    slow = 75 + 600 * sosfiltfilt(butter(4, 3.0, fs=RATE, output="sos"), rng.standard_normal(N))
    for u in (75 + 70 * np.sin(2 * np.pi * 2.0 * T), slow, np.full(N, 75.0)):
        assert hold_noise(T, u, 2e-7 * u + SIGMA * rng.standard_normal(N)) is None
    assert still_spans(slow, 600) == []
    few = np.where(T < 4.0, 20.0, 120.0)                     # two holds: too few to compare
    assert hold_noise(T, few, SIGMA * rng.standard_normal(N)) is None


@pytest.mark.slow
def test_complete_stage_with_coloured_sensor_noise_is_not_unexplained():
    """Generated PEA stage with no effect on steps, its sensor low-passed (6600022): was ``unexplained``, its model
    2.45× the white floor; the holds give the floor and the answer is ``none``, saying why. The same stage with
    white noise keeps the white floor, with the same answer and nothing said."""
    from hyst_model.diagnose.diagnose import diagnose
    from hyst_sim.generator import generate_case
    c = generate_case(6600022, "none", sensor="coloured")
    d = diagnose(c.t, c.u, c.y)
    assert d.missing == "none" and d.unexplained is None
    assert d.noise_holds is not None and d.noise == d.noise_holds > 1.5 * d.noise_white
    assert "holds" in d.explanation and d.to_json()["noise_floor_holds"] == d.noise_holds
    w = generate_case(6600022, "none")
    dw = diagnose(w.t, w.u, w.y)
    assert dw.missing == "none" and dw.noise_holds is None and dw.noise == dw.noise_white
    assert "holds" not in dw.explanation


def _coloured_case(seed: int):
    """A generated record with low-passed sensor noise, and the total noise RMS it holds (white + band-limited:
    the white stream is the white family's own, so the difference is the band-limited part)."""
    from hyst_sim.generator import generate_case
    c = generate_case(seed, "none", sensor="coloured")
    extra = c.y - generate_case(seed, "none").y
    return c, float(np.sqrt(c.noise ** 2 + np.mean(extra ** 2)))


@pytest.mark.slow
def test_sensor_noise_given_for_a_record_without_holds():
    """Generated PEA stage with no effect on sines, its sensor low-passed (6600189): no holds to read the noise in,
    ``unexplained`` at 2.4× the white floor. Given the sensor's noise (what a record at rest shows), the answer is
    ``none``; a value below what the record shows is not taken."""
    from hyst_model.diagnose.diagnose import diagnose
    c, total = _coloured_case(6600189)
    assert hold_noise(c.t, c.u, c.y) is None
    d0 = diagnose(c.t, c.u, c.y)
    assert d0.missing == "unexplained" and "this remainder may be noise" in d0.explanation   # and how to say so:
    assert "--sensor-noise" in d0.explanation
    d = diagnose(c.t, c.u, c.y, sensor_noise=total)
    assert d.missing == "none" and d.noise == d.noise_given == total and "may be noise" not in d.explanation
    assert "sensor noise given" in d.explanation and d.to_json()["noise_floor_given"] == total
    low = diagnose(c.t, c.u, c.y, sensor_noise=0.5 * d0.noise_white)
    assert low.noise == d0.noise and low.noise_given is None and low.missing == "unexplained"
    assert "the record shows more noise" in low.explanation and "than the sensor noise given" in low.explanation


def test_sensor_noise_option_refuses_what_is_not_an_rms(tmp_path):
    import subprocess
    import sys
    data = tmp_path / "rec.csv"
    np.savetxt(data, np.column_stack([T[:400], np.linspace(0, 1, 400), np.linspace(0, 1e-6, 400)]), delimiter=",",
               header="t,u,y", comments="")
    cmd = [sys.executable, "-c", "import sys; from hyst_model.cli.main import main; sys.exit(main())", "diagnose",
           str(data), "--sensor-noise"]
    for bad in ("-3e-9", "0", "nan", "three"):
        r = subprocess.run(cmd + [bad], capture_output=True, text=True, timeout=120)
        assert r.returncode == 2 and "--sensor-noise" in r.stderr and "Traceback" not in r.stderr
    from hyst_model.diagnose.diagnose import diagnose
    from hyst_model.errors import DataError
    with pytest.raises(DataError, match="sensor noise"):
        diagnose(T, np.sin(T), np.sin(T), sensor_noise=-1.0)


def test_compare_reads_the_noise_in_the_holds():
    """``hyst compare``'s findings: the exact model of a stage whose sensor adds low-passed noise is at the noise
    level read in the holds (1.9× the white part here), not "2× the output noise"; with white noise nothing is said."""
    from hyst_model.diagnose.report import findings
    from hyst_model.diagnose.stats import compare_stats
    rng = np.random.default_rng(8)
    u = _steps(rng)
    truth = _stage(u)
    y = truth + SIGMA * rng.standard_normal(N) + _coloured(rng, 40.0, 2.0 * SIGMA)
    st = compare_stats(T, u, y, truth)
    said = " ".join(findings(st))
    assert st.to_dict()["noise_holds"] > MARGIN * st.noise_sigma
    assert "held still" in said and "at the sensor noise level" in said
    white = compare_stats(T, u, truth + SIGMA * rng.standard_normal(N), truth)
    assert white.to_dict()["noise_holds"] is None and "held still" not in " ".join(findings(white))


def test_the_identification_schedule_holds_long_enough_to_read_the_noise():
    """``hyst excite``'s default schedule on the simulated PEA stage: its 0.25 s step holds are read; with the sensor's
    noise low-passed at 40 Hz the holds show it (0.8–1.1× the whole noise; the white part alone
    beneath the margin), without it they read the sensor's white noise."""
    from hyst_control.excitation import ExcitationSpec, build_excitation
    from hyst_sim.plant import Plant, PlantConfig
    ex = build_excitation(ExcitationSpec())
    plant = Plant(PlantConfig.for_profile("pea", rate=1.0 / ExcitationSpec().dt, seed=3))
    plant.reset()
    r = plant.run(np.asarray(ex.u))
    t = np.asarray(ex.t)
    h = hold_noise(t, r.u_applied, r.y)
    sensor = float(np.hypot(2e-9, 2e-9 / np.sqrt(12.0)))   # the profile's 2 nm noise and 2 nm quantisation
    assert h is not None and h.holds >= 8 and 0.85 * sensor < h.rms < 1.1 * sensor
    rng = np.random.default_rng(1)
    c = np.exp(-2 * np.pi * 40.0 / 2000.0)
    extra = 3e-9 * lfilter([np.sqrt(1 - c * c)], [1.0, -c], rng.standard_normal(t.size))
    hc = hold_noise(t, r.u_applied, r.y + extra)
    total = float(np.sqrt(h.rms ** 2 + np.mean(extra ** 2)))
    assert hc is not None and 0.8 * total < hc.rms < 1.1 * total and hc.rms > MARGIN * h.rms


def test_compare_survives_a_noiseless_record_and_does_not_call_pickup_coloured_noise():
    """A noiseless step record (white part 0) gives findings, not a division by zero; a 50 Hz line on white noise
    is named as pickup, and the holds (read without it) say nothing about noise that is not white."""
    from hyst_model.diagnose.report import findings
    from hyst_model.diagnose.stats import compare_stats
    rng = np.random.default_rng(21)
    u = _steps(rng)
    truth = _stage(u)
    clean = compare_stats(T, u, truth, truth)
    assert clean.to_dict()["noise_holds"] is None and isinstance(findings(clean), list)
    y = truth + SIGMA * rng.standard_normal(N) + 4 * SIGMA * np.sin(2 * np.pi * 50.0 * T + 0.3)
    st = compare_stats(T, u, y, truth)
    said = " ".join(findings(st))
    assert "mains pickup" in said and "held still" not in said and st.to_dict()["noise_holds"] is None


def test_the_floor_and_its_words():
    """What the floor is made of (.floor): holds and lines together, a value given above and below what the record
    shows; the holds read without the lines counted beside them."""
    from hyst_model.diagnose.colour import HeldNoise
    from hyst_model.diagnose.floor import Floor, read_floor
    from hyst_model.diagnose.lines import Line
    line = Line(50.0, 3e-9, 900.0)
    both = Floor(2e-9, HeldNoise(4e-9, 6, 2000), (line,))
    assert both.value == pytest.approx(np.hypot(4e-9, line.rms)) and not both.given_used
    w = both.words()
    assert "6 holds" in w and "50 Hz" in w and "removes them" in w
    assert "sensor noise given" not in w
    low = Floor(2e-9, HeldNoise(4e-9, 6, 2000), (), given=3e-9)
    assert low.value == 4e-9 and "the record shows more noise (4 nm) than the sensor noise given (3 nm)" in low.words()
    high = Floor(2e-9, None, (line,), given=9e-9)
    assert high.value == 9e-9 and high.given_used
    assert high.words().startswith("the noise floor 9 nm is the sensor noise given") and "50 Hz" in high.words()
    assert Floor(2e-9).words() == "" and Floor(2e-9).value == 2e-9
    rng = np.random.default_rng(22)
    u = _steps(rng)
    y = _stage(u) + SIGMA * rng.standard_normal(N) + line.signal(T)
    with_line, _ = read_floor(T, u, y, SIGMA, lines=[line])
    assert with_line.held is None and with_line.value == pytest.approx(np.hypot(SIGMA, line.rms))
    without, reading = read_floor(T, u, y, SIGMA)
    assert reading is not None and without.held is not None      # the line alone would read as "not white"


def test_sensor_noise_read_from_a_record_at_rest(tmp_path):
    """``--sensor-noise REST``: the noise of a record of the stage at rest (drift over it removed), band-limited
    noise included; a record whose input moves, a missing file or a word are one clear error each."""
    from hyst_model.cli.diagnose import sensor_noise_arg
    from hyst_model.errors import DataError
    rng = np.random.default_rng(40)
    extra = _coloured(rng, 30.0, 2.0 * SIGMA)
    y = 3e-6 + 1e-9 * T + 4e-10 * T ** 2 + SIGMA * rng.standard_normal(N) + extra   # at rest, drifting
    rest = tmp_path / "rest.csv"
    np.savetxt(rest, np.column_stack([T, np.full(N, 75.0), y]), delimiter=",", header="t,u,y", comments="")
    total = float(np.sqrt(SIGMA ** 2 + np.mean(extra ** 2)))
    assert sensor_noise_arg(str(rest)) == pytest.approx(total, rel=0.1)
    assert sensor_noise_arg("3e-9") == 3e-9 and sensor_noise_arg(None) is None
    moving = tmp_path / "moving.csv"
    np.savetxt(moving, np.column_stack([T, 75.0 + 0.1 * np.sin(T), y]), delimiter=",", header="t,u,y", comments="")
    with pytest.raises(DataError, match="the input moves"):
        sensor_noise_arg(str(moving))
    for bad in (str(tmp_path / "none.csv"), "three", "-1e-9"):
        with pytest.raises(DataError, match="--sensor-noise"):
            sensor_noise_arg(bad)
