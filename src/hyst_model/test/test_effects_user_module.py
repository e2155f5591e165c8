"""--effect-module: the documented example works everywhere a built-in does; broken modules give one clear error."""
import textwrap
from pathlib import Path

import numpy as np
import pytest

from hyst_model.cli.main import main
from hyst_model.effects import EFFECTS, load_effect_module
from hyst_model.errors import EffectError
from hyst_model.spec import build_model

EXAMPLE = Path(__file__).resolve().parents[3] / "docs" / "examples" / "my_effect.py"


def test_example_module_registers_and_composes():
    assert load_effect_module(EXAMPLE) == ["hum"]
    try:
        m = build_model("mbw", ["creep", "hum"], {"u_scale": 15.0, "y_scale": 5e-6, "hum.freq": 60.0})
        assert m.names[-2:] == ("hum.a", "hum.b") and m.config()["hum.freq"] == 60.0
        t = np.arange(1000) * 1e-3
        u = np.full(1000, 10.0)
        th = m.theta0.copy()
        th[-2] = 1e-8
        y = m.simulate(th, t, u) - m.simulate(m.theta0, t, u)
        np.testing.assert_allclose(y, 1e-8 * np.cos(2 * np.pi * 60 * t), atol=1e-20)
    finally:
        EFFECTS.pop("hum", None)


@pytest.mark.parametrize("source, message", [
    ("def broken(:\n", "syntax error at line 1"),
    ("import not_a_module_anywhere\n", "import failed: ModuleNotFoundError"),
    ("x = 1\n", "defines no subclass"),
    ("""
     from hyst_model.effects import Effect
     from hyst_model.model import Param
     class Bad(Effect):
         name = "bad_default"
         def params(self):
             return (Param("k", 5.0, 0.0, 1.0),)
     """, "default 5.0 outside"),
    ("""
     from hyst_model.effects import Effect
     class Boom(Effect):
         name = "boom"
         def output(self, theta, t, u, y):
             raise RuntimeError("kaputt")
     """, "fails its self-check: RuntimeError: kaputt"),
    ("""
     from hyst_model.effects import Effect
     class Anon(Effect):
         pass
     """, "needs a class attribute name"),
])
def test_broken_modules_raise_one_effect_error(tmp_path, source, message):
    p = tmp_path / "user_effect.py"
    p.write_text(textwrap.dedent(source))
    with pytest.raises(EffectError, match=message) as info:
        load_effect_module(p)
    assert str(p) in str(info.value) and "\n" not in str(info.value)


def test_missing_file_and_cli_exit_code(tmp_path, capsys):
    with pytest.raises(EffectError, match="no such file"):
        load_effect_module(tmp_path / "nope.py")
    bad = tmp_path / "bad.py"
    bad.write_text("raise ValueError('nope')\n")
    data = tmp_path / "d.csv"
    t = np.arange(2000) * 1e-3
    np.savetxt(data, np.c_[t, np.sin(t), np.sin(t) * 1e-6], delimiter=",", header="t,u,y", comments="")
    rc = main(["diagnose", str(data), "--effect-module", str(bad), "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "import failed: ValueError: nope" in err[0]
