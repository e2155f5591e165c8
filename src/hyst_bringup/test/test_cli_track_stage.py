"""``hyst track`` on a stage other than the embedded PEA: the params file's own stage, its range and its stroke.

A ±10 V stage (the GMA loop shape on 1 V per model unit, about ±19 µm) is neither amplifier profile. Simulated
on the embedded PEA stage its model was driven at 36–107 V and "diverged"; on its own stage every controller must
stay inside the range it was identified on, track a reference placed on its stroke, and the PID's default gains
must keep the loop gain they were tuned for (the PEA's SI gains ring at ten times it).
"""
import json

import pytest

from hyst_model.cli.main import main


def _stage(tmp_path, lo: float = -10.0, hi: float = 10.0, fit: bool = True, shape: str = "gma") -> str:
    """A params file of a ±10 V stage (``shape="pea"``: the embedded stage's model) identified at 1 kHz over
    ``lo``..``hi`` V (``fit.u_min``/``u_max``)."""
    from hyst_model.core import stage_model

    m = stage_model("gma").replace(u_scale=1.0) if shape == "gma" else stage_model("pea")
    body = "".join(f"      {k}: {v!r}\n" for k, v in m.to_dict().items())
    prov = f"    fit:\n      u_min: {lo!r}\n      u_max: {hi!r}\n" if fit else ""
    p = tmp_path / "stage10.yaml"
    p.write_text("/**:\n  ros__parameters:\n    model:\n      base: mbw\n" + body +
                 f"      u_scale: {m.u_scale!r}\n      y_scale: {m.y_scale!r}\n      dt: 0.001\n" + prov)
    return str(p)


def _track(capsys, *argv):
    assert main(["track", *argv, "--json"]) == 0, capsys.readouterr().err
    cap = capsys.readouterr()
    return json.loads(cap.out), cap.err


@pytest.mark.parametrize("algorithm", ["dppc", "dmrac", "pid", "open_loop"])
def test_a_ten_volt_stage_is_simulated_on_its_own_range_and_stroke(algorithm, capsys, tmp_path):
    out, err = _track(capsys, "--params", _stage(tmp_path), "--algorithm", algorithm, "--reference", "sine:10",
                      "--seconds", "1")
    assert out["stage"] == "params" and (out["v_min"], out["v_max"]) == (-10.0, 10.0)
    assert -10.0 <= out["u_min"] < -3.0 and 3.0 < out["u_max"] <= 10.0     # its range, and it uses it
    assert "diverges" not in err and "leave the controller model's range" not in err, err
    assert abs(out["reference_offset"]) < 1e-6 and 10e-6 < out["reference_amplitude"] < 16e-6  # centred, 1/3
    assert "oscillation" not in out, out.get("oscillation")
    assert out["rmse"] < (0.5e-6 if algorithm == "pid" else 10e-9), out["rmse"]


def test_the_peas_si_pid_gains_ring_on_that_stage_and_the_scaled_defaults_do_not(capsys, tmp_path):
    """The test of the scaling: the embedded stage's own K_p, K_i given explicitly make the ±10 V loop oscillate."""
    p = _stage(tmp_path)
    pea, _ = _track(capsys, "--params", p, "--algorithm", "pid", "--gain", "kp=1e6", "--gain", "ki=8e9",
                    "--seconds", "1")
    own, _ = _track(capsys, "--params", p, "--algorithm", "pid", "--seconds", "1")
    assert pea.get("oscillation") and "oscillation" not in own
    assert own["rmse"] < 0.2 * pea["rmse"]


def test_the_embedded_stage_is_kept_for_a_pea_fit_and_a_range_it_leaves_is_reported(capsys, tmp_path):
    pea_fit = _stage(tmp_path, 0.0, 150.0)
    out, err = _track(capsys, "--params", pea_fit, "--seconds", "0.2")
    assert out["stage"] == "embedded" and out["v_max"] == 150.0
    out, err = _track(capsys, "--params", _stage(tmp_path), "--stage", "embedded", "--seconds", "0.2")
    assert out["stage"] == "embedded" and out["range_warning"] and "leave the controller model's range" in err


def test_the_range_can_be_given_where_the_file_records_none(capsys, tmp_path):
    p = _stage(tmp_path, fit=False)
    out, _ = _track(capsys, "--params", p, "--seconds", "0.2")
    assert out["stage"] == "embedded"                        # nothing says it is another stage
    out, _ = _track(capsys, "--params", p, "--v-min", "-8", "--v-max", "8", "--seconds", "0.5")
    assert out["stage"] == "params" and -8.0 <= out["u_min"] and out["u_max"] <= 8.0


@pytest.mark.parametrize("extra,why", [
    (["--stage", "params"], "needs --params"),
    (["--v-min", "-8"], "--v-min/--v-max set the range of --stage params"),
    (["--stage", "params", "--params", "FIT0", "--v-min", "-2000", "--v-max", "5"], "within ±1000 V"),
    (["--stage", "params", "--params", "NOFIT"], "records no identified input range"),
])
def test_stage_errors_are_one_line_and_exit_2(extra, why, capsys, tmp_path):
    sub = {"FIT0": _stage(tmp_path), "NOFIT": str(tmp_path / "nofit.yaml")}
    if "NOFIT" in extra:
        (tmp_path / "nofit.yaml").write_text(open(_stage(tmp_path, fit=False)).read())
    assert main(["track", *[sub.get(a, a) for a in extra], "--seconds", "0.1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and why in err[0], err


def test_a_reference_beyond_the_stages_reach_is_said_to_be(capsys):
    """14 µm at 10 Hz about 15 µm asks the embedded stage for more than 0–150 V gives: the commands sit on the
    ends and the error is the stage's reach, not the law's; the default 10 µm stays inside."""
    out, err = _track(capsys, "--reference", "sine:10:14", "--seconds", "0.5")
    assert out["at_range_end"] > 0.01 and "the error is the range" in err
    out, err = _track(capsys, "--reference", "sine:10", "--seconds", "0.5")
    assert out["at_range_end"] == 0.0 and "the error is the range" not in err


def test_a_stage_inside_the_peas_range_but_not_the_pea_is_its_own_and_gains_add_to_the_scaled_ones(capsys, tmp_path):
    """A 20-115 V record lies inside 0-150 V but is not the PEA: auto simulates its own stage; a --gain is applied
    on top of the scaled PID defaults (it used to drop them, and the loop rang at the PEA's SI gains)."""
    out, err = _track(capsys, "--params", _stage(tmp_path, 20.0, 115.0, shape="pea"), "--algorithm", "dppc",
                      "--seconds", "0.3")
    assert out["stage"] == "params" and out["v_min"] == 20.0 and 20.0 <= out["u_min"]
    p = _stage(tmp_path)
    plain, _ = _track(capsys, "--params", p, "--algorithm", "pid", "--seconds", "1")
    tuned, _ = _track(capsys, "--params", p, "--algorithm", "pid", "--seconds", "1", "--gain", "t_filter=0.002")
    assert "oscillation" not in tuned and tuned["rmse"] < 1.5 * plain["rmse"]
    assert main(["track", "--params", p, "--seconds", "0.2"]) == 0
    assert "on the params file's stage (-10..10 V)" in capsys.readouterr().out
