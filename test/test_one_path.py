"""One path for users (issue #10): ``hyst fit --effects X`` and ``hyst diagnose --out P`` give the same model and
figure — the same interleaved hold-out, the effect configuration diagnose chose settable with ``--config``."""
import json
from pathlib import Path

import pytest

from hyst_model.cli.main import main
from hyst_model.io import read_params

BAGS = Path(__file__).resolve().parents[1] / "bags" / "hidden"


def _config_args(params_file: Path, effect: str) -> list[str]:
    """``--config`` arguments for the non-fitted settings of ``effect`` in a params file diagnose wrote."""
    spec = read_params(params_file)
    cfg = spec.model().config()
    return [a for k, v in cfg.items() if k.startswith(effect + ".") and k != "drift.span"
            for a in ("--config", f"{k}={v}")]


@pytest.mark.slow
@pytest.mark.parametrize("name", ["creep", "dynamics", "delay", "saturation"])
def test_fit_with_the_named_effect_agrees_with_diagnose_out(name, tmp_path, capsys):
    if not (BAGS / name).exists():
        pytest.skip("hidden bags not generated")
    p = tmp_path / "d.yaml"
    assert main(["diagnose", str(BAGS / name), "--json", "--quiet", "--out", str(p)]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["missing"] == name
    assert main(["fit", str(BAGS / name), "--effects", name, "--json", "--quiet"] + _config_args(p, name)) == 0
    f = json.loads(capsys.readouterr().out)
    assert "interleaved blocks" in f["split"]
    assert f["rmse"] == pytest.approx(d["ladder"][-1]["rmse"], rel=0.05)


def test_config_must_name_a_listed_effect(tmp_path, capsys):
    import numpy as np
    t = np.arange(2000) * 1e-3
    u = 75 - 70 * np.cos(2 * np.pi * t)
    csv = tmp_path / "d.csv"
    np.savetxt(csv, np.c_[t, u, 1e-7 * u], delimiter=",", header="t,u,y", comments="")
    for bad in (["--effects", "creep", "--config", "dynamics.structure=series"],
                ["--effects", "delay", "--config", "delay.side=sideways"],
                ["--effects", "delay", "--config", "side=input"],
                ["--effects", "drift", "--config", "drift.sid=sensor"],       # a typo ran the default silently
                ["--effects", "dynamics", "--config", "dynamics.structur=feedback"]):
        try:
            rc = main(["fit", str(csv), "--quiet"] + bad)
        except SystemExit as ex:
            rc = ex.code
        assert rc == 2, bad
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "Traceback" not in err, err
        if "sid=" in bad[-1] or "structur=" in bad[-1]:
            assert "has no setting" in err and "its settings are" in err, err
