"""Params file: ROS 2 parameters YAML round trip, no overwrite without force, atomic writes."""
import os
import re

import numpy as np
import pytest
import yaml

from hyst_model.errors import EffectError, ParamsError
from hyst_model.io import read_params, spec_from_model, write_params
from hyst_model.io.params_file import flatten, nest
from hyst_model.models import BASE_MODELS


def _spec():
    m = BASE_MODELS["mbw"]({"u_scale": 15.0, "y_scale": 5.42e-6})
    theta = m.pack({"zeta1": 0.4029, "psi1": 0.0345, "alpha1": -0.0394, "delta1": 0.962, "delta2": 0.9511,
                    "offset": -1.6e-6})
    return m, theta, spec_from_model(m, theta, fit={"method": "fast", "rmse": 1.2e-8}, dt=5e-4)


def test_round_trip_rebuilds_the_same_model(tmp_path):
    m, theta, spec = _spec()
    write_params(tmp_path / "p.yaml", spec)
    doc = yaml.safe_load((tmp_path / "p.yaml").read_text())
    model = doc["/**"]["ros__parameters"]["model"]
    assert model["base"] == "mbw" and "effects" not in model and model["dt"] == 5e-4  # [] has no ROS type
    assert all(isinstance(v, float) for k, v in model.items() if k not in ("base", "effects"))  # ROS typing
    back = read_params(tmp_path / "p.yaml")
    m2 = back.model()
    np.testing.assert_array_equal(back.theta(m2), theta)
    t = np.arange(500) * 5e-4
    u = 75 + 75 * np.sin(2 * np.pi * 4 * t)
    np.testing.assert_array_equal(m2.simulate(back.theta(m2), t, u), m.simulate(theta, t, u))
    assert back.fit["method"] == "fast" and back.parameters()["model.zeta1"] == 0.4029


def test_a_sample_time_from_float_differences_is_written_as_the_period_it_is():
    m, theta, _ = _spec()
    dt = float(np.median(np.diff(np.arange(20000) * 1e-3)))  # a record's median sample spacing
    assert dt != 1e-3
    assert spec_from_model(m, theta, dt=dt).config["dt"] == 1e-3
    assert spec_from_model(m, theta, dt=1 / 3000).config["dt"] == pytest.approx(1 / 3000, rel=1e-11)


def test_never_overwrites_without_force_and_leaves_no_temporaries(tmp_path):
    _, _, spec = _spec()
    p = tmp_path / "p.yaml"
    p.write_text("precious\n")
    with pytest.raises(ParamsError, match="exists; use --force"):
        write_params(p, spec)
    assert p.read_text() == "precious\n"
    write_params(p, spec, force=True)
    assert read_params(p).base == "mbw"
    assert sorted(os.listdir(tmp_path)) == ["p.yaml"]


def test_failed_write_keeps_the_old_file(tmp_path, monkeypatch):
    _, _, spec = _spec()
    p = tmp_path / "p.yaml"
    p.write_text("precious\n")

    def boom(*a, **k):
        raise OSError("disk full")
    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(ParamsError, match="disk full"):
        write_params(p, spec, force=True)
    assert p.read_text() == "precious\n" and sorted(os.listdir(tmp_path)) == ["p.yaml"]


@pytest.mark.parametrize("text,err,match", [
    ("just text", ParamsError, "not a ROS 2 parameters file"),
    ("/**:\n  ros__parameters:\n    other: 1\n", ParamsError, "no 'ros__parameters: model:'"),
    ("/**:\n  ros__parameters:\n    model:\n      base: nope\n", ParamsError, "unknown base model 'nope'"),
    ("/**:\n  ros__parameters:\n    model:\n      base: mbw\n      zeta1: 0.4\n", ParamsError, "lacks model parameter"),
    ("/**:\n  ros__parameters:\n    model:\n      base: mbw\n      effects: [nosuch]\n", EffectError, "nosuch"),
])
def test_bad_files(tmp_path, text, err, match):
    (tmp_path / "p.yaml").write_text(text)
    with pytest.raises(err, match=match):
        read_params(tmp_path / "p.yaml")
    with pytest.raises(ParamsError, match="no such"):
        read_params(tmp_path / "missing.yaml")


def test_flatten_nest_inverse():
    d = {"zeta1": 1.0, "creep": {"gain": 2.0, "tau": {"a": 3.0}}}
    assert nest(flatten(d)) == d and flatten(d)["creep.tau.a"] == 3.0


def test_garbage_missing_scales_and_bad_dt_are_one_clear_error(tmp_path):
    from hyst_model.errors import ParamsError
    from hyst_model.io import read_params
    bad = tmp_path / "garbage.bin"
    bad.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(ParamsError, match="cannot read params file") as e:
        read_params(bad)
    assert "\n" not in str(e.value)
    broken = tmp_path / "broken.yaml"  # a YAML error was six lines, cut mid-word
    broken.write_text("/**:\n  ros__parameters:\n    model: [1, 2\n   zeta1: 0.3\n")
    with pytest.raises(ParamsError, match=r"cannot read params file \(ParserError: .* at line 4, column 9\)$") as e:
        read_params(broken)
    assert "\n" not in str(e.value)
    from hyst_model.core import pea_default
    vals = "".join(f"      {k}: {v!r}\n" for k, v in pea_default().to_dict().items()
                   if k not in ("u_scale", "y_scale", "offset"))
    base = "/**:\n  ros__parameters:\n    model:\n      base: mbw\n      offset: 0.0\n" + vals
    p = tmp_path / "noscale.yaml"
    p.write_text(base + "      y_scale: 5.0e-06\n")
    with pytest.raises(ParamsError, match="model.u_scale missing"):
        read_params(p)
    p.write_text(base + "      u_scale: 15.0\n      y_scale: 5.0e-06\n      dt: 0\n")
    with pytest.raises(ParamsError, match="model.dt must be a positive number"):
        read_params(p)


@pytest.mark.parametrize("force", [False, True])
def test_written_with_the_user_umask_also_after_force(tmp_path, force):
    _, _, spec = _spec()
    p = tmp_path / "p.yaml"
    if force:
        p.write_text("old\n")
        p.chmod(0o644)
    old = os.umask(0o022)
    try:
        write_params(p, spec, force=force)
    finally:
        os.umask(old)
    assert (p.stat().st_mode & 0o777) == 0o644


@pytest.mark.parametrize("target,match", [
    ("/proc/self/nope.yaml", "special file system"),
    ("{tmp}/missing/p.yaml", "does not exist"),
    ("{tmp}", "is a directory"),
])
def test_unwritable_targets_refused_before_work(tmp_path, target, match):
    _, _, spec = _spec()
    with pytest.raises(ParamsError, match=match):
        write_params(target.format(tmp=tmp_path), spec, force=True)


def test_diagnose_refuses_an_existing_out_before_any_work(tmp_path, capsys):
    """`hyst diagnose DATA --out P` with P present: refused at once (it used to be after minutes of fitting)."""
    from hyst_model.cli.main import main
    from hyst_model.io import write_csv
    t = np.arange(2000) * 5e-4
    write_csv(tmp_path / "r.csv", {"t": t, "u": 75 + 60 * np.sin(t), "y": 1e-6 * np.sin(t)})
    (tmp_path / "p.yaml").write_text("keep me\n")
    assert main(["diagnose", str(tmp_path / "r.csv"), "--out", str(tmp_path / "p.yaml"), "--quiet"]) == 2
    assert "exists; use --force" in capsys.readouterr().err
    assert (tmp_path / "p.yaml").read_text() == "keep me\n"


def test_a_key_no_effect_has_is_refused_and_every_variants_keys_are_read(tmp_path):
    """A mistyped key in an effect's section (``drift.sid``) ran the effect with its default without a word; now
    it is one clear error naming the effect's keys. Keys of the effect's other configurations (a node's
    parameter dump holds the feedback structure's with a series mode) still read, and are not used."""
    from hyst_model.effects import compose
    m = compose(BASE_MODELS["mbw"]({"u_scale": 15.0, "y_scale": 5.42e-6, "dt": 5e-4}), ["drift", "dynamics"],
                {"u_scale": 15.0, "y_scale": 5.42e-6, "dt": 5e-4})
    write_params(tmp_path / "p.yaml", spec_from_model(m, m.theta0, dt=5e-4))
    doc = yaml.safe_load((tmp_path / "p.yaml").read_text())
    model = doc["/**"]["ros__parameters"]["model"]
    model["dynamics"]["gain"] = 1.0  # the feedback structure's parameter beside a series mode
    (tmp_path / "dump.yaml").write_text(yaml.safe_dump(doc))
    assert read_params(tmp_path / "dump.yaml").model().effects[1].structure == "series"
    model["drift"]["sid"] = "sensor"
    (tmp_path / "typo.yaml").write_text(yaml.safe_dump(doc))
    with pytest.raises(ParamsError, match=r"model\.drift\.sid is none of drift's parameters or settings \(.*side"):
        read_params(tmp_path / "typo.yaml")


def _mbw_file(tmp_path, extra: str, name: str = "p.yaml"):
    from hyst_model.core import pea_default

    m = pea_default()
    body = "".join(f"      {k}: {v!r}\n" for k, v in m.to_dict().items() if k not in extra)
    p = tmp_path / name
    p.write_text("/**:\n  ros__parameters:\n    model:\n      base: mbw\n      u_scale: 1.0\n      y_scale: 1.0e-6\n"
                 + body + extra)
    return p


def test_numbers_yaml_1_1_leaves_as_strings_are_numbers_and_words_are_refused(tmp_path):
    """PyYAML reads 1e-6 (no decimal point) as a string: 'lacks model parameter zeta2' for a key that was there."""
    from hyst_model.io import read_params

    spec = read_params(_mbw_file(tmp_path, "      zeta2: 1e-6\n      dt: 1e-3\n"))
    assert spec.values["zeta2"] == 1e-6 and spec.config["dt"] == 1e-3
    with pytest.raises(ParamsError, match=r"model\.zeta2 is not a number \('abc'\)"):
        read_params(_mbw_file(tmp_path, "      zeta2: abc\n"))


@pytest.mark.parametrize(("extra", "why"), [
    ("      zeta3: 0.5\n", "model.zeta3: not a parameter or setting of mbw"),
    ("      creep:\n        gain: 0.5\n", "effect 'creep' is not in model.effects"),
])
def test_a_key_the_model_cannot_use_is_refused_not_ignored(tmp_path, extra, why):
    """An unknown key (a typo) and an effect's section without the effect listed ran as if absent."""
    from hyst_model.io import read_params

    with pytest.raises(ParamsError, match=re.escape(why)):
        read_params(_mbw_file(tmp_path, extra))


def _effects_file(tmp_path, effects, edit, cfg=None):
    """A params file of mbw + ``effects`` as ``hyst fit`` writes it, then ``edit(model_section)`` by hand."""
    from hyst_model.effects import compose
    c = {"u_scale": 15.0, "y_scale": 5.42e-6, "dt": 5e-4, **(cfg or {})}
    m = compose(BASE_MODELS["mbw"](c), effects, c)
    write_params(tmp_path / "fit.yaml", spec_from_model(m, m.theta0, dt=5e-4), force=True)
    doc = yaml.safe_load((tmp_path / "fit.yaml").read_text())
    edit(doc["/**"]["ros__parameters"]["model"])
    (tmp_path / "hand.yaml").write_text(yaml.safe_dump(doc))
    return tmp_path / "hand.yaml"


@pytest.mark.parametrize(("effects", "key", "value", "why"), [
    (["delay"], "delay.tau", -0.5, r"model\.delay\.tau = -0\.5 s lies outside its range \[0, 0\.05\] s"),
    (["creep"], "creep.tilt", 42.0, r"model\.creep\.tilt = 42 lies outside its range \[-0\.3, 0\.3\]"),
    ([], "psi1", 3.0, r"model\.psi1 = 3 lies outside its range"),
])
def test_a_value_outside_its_parameters_range_is_refused(tmp_path, effects, key, value, why):
    """A hand-written ``delay.tau: -0.5`` ran as no delay and ``creep.tilt: 42`` without a word; the range is the
    one the fitters search and the checks hold on (``Model.bounds``), and a value on it still reads."""
    def edit(model, v=value):
        head, _, tail = key.rpartition(".")
        (model[head] if head else model)[tail] = v
    with pytest.raises(ParamsError, match=why):
        read_params(_effects_file(tmp_path, effects, edit))
    m = read_params(_effects_file(tmp_path, effects, lambda model: None)).model()
    lo, hi = m.bounds
    i = m.names.index(key)
    read_params(_effects_file(tmp_path, effects, lambda model: edit(model, float(hi[i]))))  # on the bound: fine


def test_drift_offsets_beyond_its_knots_are_refused_not_ignored(tmp_path):
    """``knots`` lowered by hand to 3 left c4 and c5 in the file, read and never used (1 mm in them changed
    nothing); ``knots`` of 0 or 2.5 and a non-finite span are refused when the model is built."""
    def lower(model):
        model["drift"]["knots"] = 3.0
    with pytest.raises(ParamsError, match=r"model\.drift\.c4 is none of drift's parameters"):
        read_params(_effects_file(tmp_path, ["drift"], lower))
    def lower_and_drop(model):
        lower(model)
        del model["drift"]["c4"], model["drift"]["c5"]
    assert read_params(_effects_file(tmp_path, ["drift"], lower_and_drop)).model().names[-1] == "drift.c3"
    for key, v, why in (("knots", 0.0, "drift.knots must be a whole number between 1 and 100, not 0"),
                        ("knots", 2.5, "not 2.5"), ("span", float("nan"), "drift.span must be a finite number")):
        def bad(model, key=key, v=v):
            model["drift"][key] = v
        with pytest.raises((ParamsError, EffectError), match=re.escape(why)):
            read_params(_effects_file(tmp_path, ["drift"], bad))
