"""Remark 4.1 and parameters on their bounds are reported for every fit (never silent)."""
from __future__ import annotations

import json

import numpy as np

from hyst_model.cli.main import main
from hyst_model.core import pea_default
from hyst_model.identify.admissible import check_admissible
from hyst_model.io import write_csv
from hyst_model.models import data_config
from hyst_model.spec import build_model


def _model():
    return build_model("mbw", (), dict(data_config(np.r_[0.0, 150.0], np.r_[0.0, 30e-6]), dt=5e-4))


def test_thesis_table_4_1_is_admissible_and_a_violation_is_named():
    m = _model()
    p = pea_default()
    vals = {**p.to_dict(), "offset": 0.0}
    th = np.array([vals[n] for n in m.names])
    a = check_admissible(m, th)
    assert a.remark_4_1 is (p.alpha1 < -abs(p.psi1) and p.alpha2 < -abs(p.psi2))
    th_bad = th.copy()
    th_bad[m.names.index("alpha2")] = 0.01
    b = check_admissible(m, th_bad)
    assert b.remark_4_1 is False and any(v.startswith("alpha2 = 0.01") for v in b.violations)
    assert "μ floored" in b.controllers
    assert "refit with --admissible" in b.controllers  # the constrained fit is offered where Remark 4.1 fails
    assert a.remark_4_1 and "--admissible" not in a.controllers  # Table 4.1 holds it: nothing to offer
    lo, _ = m.bounds
    th_edge = th.copy()
    th_edge[m.names.index("psi2")] = lo[m.names.index("psi2")]
    assert any(s.startswith("psi2") and "lower bound" in s for s in check_admissible(m, th_edge).at_bounds)


def test_a_model_that_diverges_within_its_record_range_is_reported():
    """The probe (identify.admissible.probe_bounded) runs the model on inputs within the record's range; a fit
    that is finite on its record and diverges off it is reported, never silent. Without a record nothing is probed."""
    m = _model()
    p = pea_default()
    vals = {**p.to_dict(), "offset": 0.0}
    th = np.array([vals[n] for n in m.names])
    t = np.arange(4000) * 5e-4
    u = 75 + 60 * np.sin(2 * np.pi * 2 * t)
    y = m.simulate(th, t, u)
    ok = check_admissible(m, th, record=(t, u, y))
    assert ok.bounded is True and ok.clean and ok.divergence == ""
    th_bad = th.copy()
    th_bad[m.names.index("alpha1")] = 3.0  # finite on a sine, not on steps between the range's ends
    assert np.all(np.isfinite(m.simulate(th_bad, t, u)))
    bad = check_admissible(m, th_bad, record=(t, u, y))
    assert bad.bounded is False and not bad.clean
    assert "steps between its ends" in bad.divergence and bad.controllers.startswith("unstable off its record")
    assert check_admissible(m, th_bad).bounded is None
    # ψ ≥ 0 here: the divergence hint does not offer the constrained fit as its cure (Remark 4.1's verdict, after
    # it, does offer it for α1 = 3, which violates the Remark)
    assert "keeps the rate terms passive" not in bad.controllers
    th_neg = th.copy()
    th_neg[m.names.index("psi2")] = -1.0  # anti-damping rate term: runs away once the input moves fast
    neg = check_admissible(m, th_neg, record=(t, u, y))
    assert neg.bounded is False and "hyst fit --admissible keeps the rate terms passive" in neg.controllers


def test_hyst_fit_reports_admissibility_in_json_and_text(tmp_path, capsys):
    t = np.arange(4000) * 5e-4
    u = 75 + 60 * np.sin(2 * np.pi * 2 * t) + 10 * np.sin(2 * np.pi * 9 * t)
    y = pea_default().simulate(u) + 2e-9 * np.random.default_rng(0).standard_normal(t.size)
    csv = tmp_path / "r.csv"
    write_csv(csv, {"t": t, "u": u, "y": y})
    assert main(["fit", str(csv), "--json", "--quiet"]) == 0
    adm = json.loads(capsys.readouterr().out)["admissibility"]
    assert set(adm) == {"remark_4_1", "violations", "at_bounds", "controllers", "bounded", "divergence"}
    assert adm["controllers"] and adm["bounded"] is True and adm["divergence"] == ""
    assert main(["fit", str(csv), "--quiet"]) == 0
    assert "controllers:" in capsys.readouterr().out


def test_hyst_diagnose_checks_the_model_it_hands_on_as_hyst_fit_does(tmp_path, capsys):
    """One path: the model diagnose names (and ``--out`` saves) gets the same Remark 4.1 / bounds check as a fit,
    in the JSON, the text and the params file's provenance."""
    import yaml
    t = np.arange(4000) * 5e-4
    u = 75 + 60 * np.sin(2 * np.pi * 2 * t) + 10 * np.sin(2 * np.pi * 9 * t)
    y = pea_default().simulate(u) + 2e-9 * np.random.default_rng(0).standard_normal(t.size)
    csv = tmp_path / "r.csv"
    write_csv(csv, {"t": t, "u": u, "y": y})
    out = tmp_path / "p.yaml"
    main(["diagnose", str(csv), "--json", "--quiet", "--out", str(out)])
    obj = json.loads(capsys.readouterr().out)
    adm = obj["admissibility"]
    assert set(adm) == {"remark_4_1", "violations", "at_bounds", "controllers", "bounded", "divergence"}
    assert adm["controllers"] and adm["bounded"] is True and adm["divergence"] == ""
    spec = yaml.safe_load(out.read_text())
    assert adm["controllers"] in json.dumps(spec, ensure_ascii=False)  # the params file says the same
    main(["diagnose", str(csv), "--quiet"])
    assert f"controllers ({obj['ladder'][-1]['model']}): {adm['controllers']}" in capsys.readouterr().out
