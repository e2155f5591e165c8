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


def test_readme_example_works_in_fit_and_simulate_and_a_builtin_name_is_refused(tmp_path, capsys):
    """`hyst fit ... --effects hum --effect-module docs/examples/my_effect.py` (README) and `hyst simulate` on its
    params file; a user effect named like a built-in is refused instead of replacing it."""
    from hyst_model.core import pea_default
    from hyst_model.io import write_csv
    try:
        t = np.arange(4000) * 5e-4
        u = 75 + 60 * np.sin(2 * np.pi * 2 * t)
        y = pea_default().simulate(u) + 3e-9 * np.cos(2 * np.pi * 50 * t)
        write_csv(tmp_path / "r.csv", {"t": t, "u": u, "y": y})
        write_csv(tmp_path / "u.csv", {"t": t, "u": u})
        p = tmp_path / "p.yaml"
        assert main(["fit", str(tmp_path / "r.csv"), "--effects", "hum", "--effect-module", str(EXAMPLE),
                     "--out", str(p), "--quiet"]) == 0
        EFFECTS.pop("hum", None)                       # a fresh process would not know it either
        assert main(["simulate", "--params", str(p), "--input", str(tmp_path / "u.csv"),
                     "--out", str(tmp_path / "y.csv")]) == 2
        assert "hum" in capsys.readouterr().err
        assert main(["simulate", "--params", str(p), "--input", str(tmp_path / "u.csv"),
                     "--out", str(tmp_path / "y.csv"), "--effect-module", str(EXAMPLE)]) == 0
    finally:
        EFFECTS.pop("hum", None)
    clash = tmp_path / "clash.py"
    clash.write_text(textwrap.dedent('''
        from hyst_model.effects import Effect
        class MyCreep(Effect):
            name = "creep"
            kind = "output"
            def params(self):
                return ()
            def output(self, theta, t, u, y):
                return y
        '''))
    builtin = EFFECTS["creep"]
    with pytest.raises(EffectError, match="'creep', a built-in effect"):
        load_effect_module(clash)
    assert EFFECTS["creep"] is builtin
