"""``hyst track`` through the real dispatcher: JSON metrics, and one-line errors with exit code 2."""
import json

import pytest

from hyst_model.cli.main import main


def test_track_json_reports_rmse_and_mae_in_metres(capsys):
    assert main(["track", "--algorithm", "dppc", "--reference", "sine:10", "--seconds", "0.3", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["algorithm"] == "dppc" and out["samples"] == 600
    assert 1e-10 < out["rmse"] < 20e-9 and out["rmse"] <= out["mae"] < 100e-9  # noise-limited, in metres


def test_track_pid_is_worse_than_dppc_at_30_hz(capsys):
    res = {}
    for alg in ("pid", "dppc"):
        main(["track", "--algorithm", alg, "--reference", "sine:30", "--seconds", "0.3", "--json"])
        res[alg] = json.loads(capsys.readouterr().out)["rmse"]
    assert res["pid"] > 10 * res["dppc"]


def test_gain_overrides_reproduce_table_5_6_trend_from_cs3(capsys):
    """Thesis Table 5.6: from CS3 on Case 3, κ = 0.5 tracks far better than κ = 0.01."""
    rmse = {}
    for k in ("0.01", "0.5"):
        assert main(["track", "--algorithm", "dmrac", "--initial", "cs3", "--reference", "case3", "--seconds", "2",
                     "--gain", f"kappa1={k}", "--gain", f"kappa2={k}", "--json"]) == 0
        rmse[k] = json.loads(capsys.readouterr().out)["rmse"]
    assert rmse["0.5"] < 0.2 * rmse["0.01"]


@pytest.mark.parametrize("argv", [["track", "--reference", "sine"], ["track", "--seconds", "-1"],
                                  ["track", "--gain", "chi=2"], ["track", "--gain", "nope=1"],
                                  ["track", "--algorithm", "open_loop", "--gain", "ki=1"],
                                  ["track", "--mismatch", "3"], ["track", "--algorithm", "dmrac", "--initial", "x"],
                                  ["track", "--algorithm", "pid", "--initial", "cs1"],  # ignored silently before
                                  ["track", "--algorithm", "pid", "--thesis-rate"],
                                  ["track", "--no-effects"],  # without --params: ignored silently before
                                  ["track", "--algorithm", "pid", "--gain", "ki=0.5", "--gain", "ki=0.7"],
                                  ["track", "--gain", "exact_rate=on"],  # read as false before
                                  ["track", "--gain", "exact_rate=2"],
                                  ["track", "--thesis-rate", "--gain", "exact_rate=true"]])  # rate taken silently
def test_bad_input_is_one_line_and_exit_2(argv, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("hyst track: error:") and "Traceback" not in "".join(err)


def test_stability_options_without_a_resonance_are_noted_not_ignored(capsys):
    assert main(["track", "--stability", "refuse", "--seconds", "0.05"]) == 0
    assert "note: --stability and --notch act on a resonance" in capsys.readouterr().err
    assert main(["track", "--seconds", "0.05"]) == 0
    assert "note:" not in capsys.readouterr().err


def _params(tmp_path, effects: str = "") -> str:
    """The embedded stage's model at 2 kHz as a params file, with an identified 3-sample input delay."""
    from hyst_model.core import pea_default

    m = pea_default()
    body = "".join(f"      {k}: {v!r}\n" for k, v in m.to_dict().items())
    p = tmp_path / "stage.yaml"
    p.write_text("/**:\n  ros__parameters:\n    model:\n      base: mbw\n" + effects + body +
                 f"      u_scale: {m.u_scale!r}\n      y_scale: {m.y_scale!r}\n      dt: 0.0005\n"
                 "      delay:\n        tau: 0.0015\n        side: input\n")
    return str(p)


def test_track_with_the_identified_model_against_a_hidden_scenario(capsys, tmp_path):
    """--params P --scenario S: the delay of P is compensated on the hidden-delay stage; --no-effects is not."""
    p = _params(tmp_path, "      effects: [delay]\n")
    res = {}
    for extra in ([], ["--no-effects"]):
        assert main(["track", "--params", p, "--scenario", "hidden_delay", "--reference", "sine:5", "--seconds",
                     "0.5", "--json", *extra]) == 0
        res[bool(extra)] = json.loads(capsys.readouterr().out)
    assert res[False]["compensated"] == ["delay"] and res[True]["compensated"] == []
    assert res[False]["rmse"] < 20e-9 < 10 * res[False]["rmse"] < res[True]["rmse"]


@pytest.mark.parametrize("extra", [["--scenario", "nope"], ["--rate", "1000"], ["--params", "/nope.yaml"]])
def test_track_params_and_scenario_errors_are_one_line(extra, capsys, tmp_path):
    argv = ["track", "--params", _params(tmp_path), *extra]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "error" in err[0]


@pytest.mark.parametrize("algorithm", ["dppc", "dmrac", "pid", "open_loop"])
def test_track_on_a_resonant_stage_is_derated_with_a_warning_or_stable(algorithm, capsys):
    """``hyst track --resonance 350:0.04`` (the hidden dynamics scenario): default gains are derated with a warning
    and track; ``--stability warn`` runs them and the loop is unstable; ``refuse`` is one line, exit 2."""
    assert main(["track", "--algorithm", algorithm, "--resonance", "350:0.04", "--seconds", "1", "--json"]) == 0
    cap = capsys.readouterr()
    out = json.loads(cap.out)
    assert out["finite"] and out["rmse"] < (10e-6 if algorithm == "pid" else 0.3e-6)
    if algorithm == "open_loop":
        assert cap.err == "" and out["derated"] == {}
        return
    assert "derated" in cap.err and out["derated"] and out["spectral_radius"] < 1
    assert main(["track", "--algorithm", algorithm, "--resonance", "350:0.04", "--seconds", "1", "--stability",
                 "warn", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["rmse"] > 5e-6
    assert main(["track", "--algorithm", algorithm, "--resonance", "350:0.04", "--stability", "refuse"]) == 2
    assert "unstable" in capsys.readouterr().err


def test_track_pid_runs_a_notch_at_the_resonance_unless_told_not_to(capsys):
    """PID on the resonant stage: by default with a notch at 350 Hz (and less derating, a better 10 Hz sine);
    ``--no-notch`` derates the gains alone."""
    runs = {}
    for flag in ("--notch", "--no-notch"):
        assert main(["track", "--algorithm", "pid", "--resonance", "350:0.04", "--seconds", "1", flag, "--json"]) == 0
        runs[flag] = json.loads(capsys.readouterr().out)
    assert runs["--notch"]["derated"].get("notch_fn") == 350.0 and "notch_fn" not in runs["--no-notch"]["derated"]
    assert runs["--notch"]["derated"]["kp"] > 2 * runs["--no-notch"]["derated"]["kp"]
    assert runs["--notch"]["rmse"] < 0.5 * runs["--no-notch"]["rmse"]


def test_a_model_that_runs_away_within_the_limits_is_refused_open_loop_and_reported_for_dppc(capsys, tmp_path):
    """As the controller node decides (hyst_control.controller_settings.model_divergence): the open-loop inverse
    would follow the runaway prediction (exit 2, one line); DPPC runs with the warning."""
    from hyst_model.core import pea_default

    m = pea_default().replace(alpha1=0.9)  # finite on a sine, not finite on steps across 0–150 V
    body = "".join(f"      {k}: {v!r}\n" for k, v in m.to_dict().items())
    p = tmp_path / "runaway.yaml"
    p.write_text("/**:\n  ros__parameters:\n    model:\n      base: mbw\n" + body + "      dt: 0.0005\n")
    assert main(["track", "--params", str(p), "--algorithm", "open_loop", "--seconds", "0.1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "diverges" in err[0] and "open-loop inverse" in err[0]
    assert main(["track", "--params", str(p), "--algorithm", "dppc", "--seconds", "0.1", "--json"]) == 0
    assert "diverges" in capsys.readouterr().err
    ok = tmp_path / "ok.yaml"
    ok.write_text(p.read_text().replace("alpha1: 0.9", f"alpha1: {pea_default().alpha1!r}"))
    assert main(["track", "--params", str(ok), "--algorithm", "open_loop", "--seconds", "0.1", "--json"]) == 0
    assert "diverges" not in capsys.readouterr().err
