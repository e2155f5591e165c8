"""A user effect that fails only deep inside a run (issue #13): one line naming the effect and where, exit 2 —
or, in diagnose, that candidate's fit failed with the same sentence — never a traceback."""
import json

import numpy as np
import pytest

from hyst_model.cli.main import main

FLAKY = '''
import numpy as np
from hyst_model.effects import Effect
from hyst_model.model import Param


class Flaky(Effect):
    """Works on the short self-check, divides by zero on any record longer than 1000 samples."""
    name = "flaky_{tag}"
    summary = "fails on long records"
    physics = "none"
    kind = "output"

    def params(self):
        return (Param("a", 0.0, -1e-6, 1e-6, "m", "offset"),)

    def output(self, theta, t, u, y):
        if len(t) > 1000:
            1 / 0
        return y + theta[0]

    def signature(self, t, u, residual, dt):
        return 0.0, "never"
'''


def _data(tmp_path):
    t = np.arange(4000) * 1e-3
    u = 75 - 70 * np.cos(2 * np.pi * t)
    p = tmp_path / "d.csv"
    np.savetxt(p, np.c_[t, u, 2e-7 * u + 1e-9 * np.random.default_rng(0).standard_normal(t.size)],
               delimiter=",", header="t,u,y", comments="")
    return p


@pytest.mark.parametrize("tag", ["fit", "diag"])
def test_failing_user_effect_is_one_line_naming_it(tmp_path, capsys, tag):
    mod = tmp_path / f"flaky_{tag}.py"
    mod.write_text(FLAKY.replace("{tag}", tag))
    data = _data(tmp_path)
    if tag == "fit":
        rc = main(["fit", str(data), "--effects", f"flaky_{tag}", "--effect-module", str(mod), "--quiet"])
        err = capsys.readouterr().err
        assert rc == 2 and "Traceback" not in err
        assert err.strip().count("\n") == 0 and f"user effect 'flaky_{tag}'" in err and "ZeroDivisionError" in err
    else:
        rc = main(["diagnose", str(data), "--effect-module", str(mod), "--effects", f"flaky_{tag},drift",
                   "--json", "--quiet"])
        captured = capsys.readouterr()
        assert rc in (0, 3) and "Traceback" not in captured.err
        obj = json.loads(captured.out)
        ev = [c["evidence"] for c in obj["candidates"] if c["effect"] == f"flaky_{tag}"][0]
        assert f"user effect 'flaky_{tag}'" in ev and "failed in output()" in ev, ev


def test_an_effect_module_that_exits_at_import_is_an_error_not_a_silent_exit_0(tmp_path, capsys):
    mod = tmp_path / "quitter.py"
    mod.write_text("import sys\nsys.exit(0)\n")
    rc = main(["fit", str(_data(tmp_path)), "--effects", "hum", "--effect-module", str(mod), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and "called sys.exit(0)" in err and "Traceback" not in err
