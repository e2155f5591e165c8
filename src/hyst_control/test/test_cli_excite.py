"""``hyst excite``: writes the excitation the node would play as a t,u CSV; refuses bad input in one line."""
import json

import numpy as np
import pytest

from hyst_control.excitation import ExcitationSpec, build_excitation, from_samples
from hyst_model.cli.main import main as hyst
from hyst_model.io.csvio import read_input_csv


def test_writes_the_generated_excitation_and_describes_it(tmp_path, capsys):
    out = tmp_path / "u.csv"
    rc = hyst(["excite", "--out", str(out), "--profile", "gma", "--rate", "2000", "--parts", "steps,noise,sweep",
               "--seed", "5", "--json"])
    assert rc == 0
    desc = json.loads(capsys.readouterr().out)
    t, u = read_input_csv(out)
    ex = build_excitation(ExcitationSpec(v_min=-5.0, v_max=5.0, slew_max=_gma_slew(), dt=1 / 2000,
                                         parts=("steps", "noise", "sweep"), seed=5))
    np.testing.assert_allclose(u, ex.u, rtol=1e-9, atol=1e-9)  # %.10g in the file
    np.testing.assert_allclose(t, ex.t, rtol=1e-9, atol=1e-12)
    assert desc["samples"] == u.size and desc["rate"] == 2000.0 and desc["rest"] == 0.0
    assert [s["part"] for s in desc["segments"]] == ["steps", "noise", "sweep"]
    assert -5.0 <= desc["u_min"] < 0.0 < desc["u_max"] <= 5.0
    # what the node accepts: the file's own samples pass the player's checks unchanged
    assert np.array_equal(from_samples(t, u, ExcitationSpec(v_min=-5.0, v_max=5.0, slew_max=_gma_slew(),
                                                            dt=1 / 2000)).u, u)


def _gma_slew() -> float:
    from hyst_common.profiles import GMA_LIMITS
    return float(min(GMA_LIMITS.slew_max, 1e9))


@pytest.mark.parametrize("extra,why", [
    (["--parts", "steps,chirp"], "unknown excitation part"),
    (["--v-max", "200"], "leave the pea amplifier's range"),
    (["--f-hi", "900", "--rate", "1000"], "Nyquist"),
    (["--amplitudes", "0.5,x"], "comma list of numbers"),
    (["--rate", "0"], "--rate"),
    (["--profile", "custom", "--v-max", "10"], "--profile custom needs --v-min and --v-max"),
    (["--profile", "custom", "--v-min", "-2000", "--v-max", "10"], "within ±1000 V"),
    (["--profile", "custom", "--v-min", "5", "--v-max", "-5"], "v_min < v_max"),
])
def test_bad_arguments_are_one_line_exit_2_and_write_nothing(tmp_path, capsys, extra, why):
    out = tmp_path / "u.csv"
    assert hyst(["excite", "--out", str(out), *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and why in err, err
    assert not out.exists()


def test_a_band_the_parts_do_not_use_is_not_checked_and_unused_options_are_noted(tmp_path, capsys):
    """Steps only at 10 Hz: the multisine band's defaults (0.5-50 Hz) refused it against a 5 Hz Nyquist; options
    only other parts use were taken without a word."""
    assert hyst(["excite", "--out", str(tmp_path / "a.csv"), "--rate", "10", "--parts", "steps", "--hold", "1"]) == 0
    assert "note:" not in capsys.readouterr().err
    assert hyst(["excite", "--out", str(tmp_path / "b.csv"), "--parts", "steps", "--f-lo", "1", "--f-hi", "10",
                 "--amplitudes", "0.5"]) == 0
    assert "note: --f-lo, --f-hi, --amplitudes not used by the parts steps" in capsys.readouterr().err
    assert hyst(["excite", "--out", str(tmp_path / "c.csv"), "--rate", "10", "--parts", "sweep"]) == 2  # it uses it
    assert "Nyquist" in capsys.readouterr().err and not (tmp_path / "c.csv").exists()


def test_an_existing_file_is_kept_without_force(tmp_path, capsys):
    out = tmp_path / "u.csv"
    out.write_text("mine\n")
    assert hyst(["excite", "--out", str(out)]) == 2
    assert out.read_text() == "mine\n" and "--force" in capsys.readouterr().err
    assert hyst(["excite", "--out", str(out), "--force", "--parts", "steps"]) == 0
    assert out.read_text().startswith("t,u\n")


def test_a_custom_range_for_another_stage_is_written_and_the_play_command_names_it(tmp_path, capsys):
    """A ±10 V stage is neither profile: ``--profile custom`` takes its range; the rest is 0 V, the centre."""
    out = tmp_path / "u.csv"
    rc = hyst(["excite", "--out", str(out), "--profile", "custom", "--v-min", "-10", "--v-max", "10",
               "--parts", "steps,sines", "--json"])
    assert rc == 0
    cap = capsys.readouterr()
    desc = json.loads(cap.out)
    t, u = read_input_csv(out)
    assert -10.0 <= u.min() < -5.0 and 5.0 < u.max() <= 10.0 and desc["rest"] == 0.0 and u[0] == u[-1] == 0.0
    slew = np.max(np.abs(np.diff(u))) / (t[1] - t[0])
    assert slew <= 20.0 / 1e-3 * (1 + 1e-9)      # the default: a full swing in no less than 1 ms
    assert "-p profile:=custom -p v_min:=-10.0 -p v_max:=10.0" in cap.err   # what the node must be told


@pytest.mark.parametrize("lo,hi,rest", [(-30.0, 120.0, 0.0), (-120.0, -20.0, -20.0), (20.0, 120.0, 20.0)])
def test_a_custom_excitation_rests_where_the_stage_rests(tmp_path, capsys, lo, hi, rest):
    """0 V where the range holds it, else the end nearer 0 V: the stage's v_safe (custom_limits), so the player
    starts where the stage is (a −30…120 V range rested at its centre, 45 V, a 45 V jump at the start)."""
    from hyst_common.profiles import custom_limits

    out = tmp_path / "u.csv"
    assert hyst(["excite", "--out", str(out), "--profile", "custom", "--v-min", str(lo), "--v-max", str(hi),
                 "--parts", "steps,sines", "--json"]) == 0
    desc = json.loads(capsys.readouterr().out)
    _, u = read_input_csv(out)
    assert desc["rest"] == rest == custom_limits(lo, hi).v_safe and u[0] == u[-1] == rest
    assert lo <= u.min() and u.max() <= hi and u.max() - u.min() > 0.5 * (hi - lo)
