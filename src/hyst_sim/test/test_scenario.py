"""Hidden scenario files and params files: loading, merging, and that nothing echoes hidden values."""
import numpy as np
import pytest

from hyst_model.core import pea_default
from hyst_sim.errors import ConfigError, ScenarioError
from hyst_sim.plant import Plant, PlantConfig
from hyst_sim.scenario import load_params_file, load_scenario, scenario_dir

SHIPPED = ["hidden_none", "hidden_creep", "hidden_asymmetry", "hidden_dynamics", "hidden_delay", "hidden_drift",
           "hidden_saturation", "hidden_creep_delay"]


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_scenarios_load_and_switch_on_exactly_their_effects(name):
    cfg = PlantConfig.from_scenario(scenario_dir() / f"{name}.yaml")
    expected = set(name.removeprefix("hidden_").split("_")) - {"none"}
    assert set(cfg.effects.active()) == expected | {"noise", "quantization"}
    assert cfg.mbw == pea_default()
    s = load_scenario(scenario_dir() / f"{name}.yaml")
    assert repr(s) == str(s) == "Scenario(<hidden>)"
    for eff in expected:
        assert eff not in repr(s)


def test_hidden_effects_are_visible_in_the_data_but_realistic():
    """Each shipped effect changes a 1 Hz full-stroke sine response by more than the 2 nm sensor, < 10 % stroke."""
    t = np.arange(4000) * 1e-3
    u = 75 - 75 * np.cos(2 * np.pi * t)
    ref = Plant(PlantConfig.for_profile("pea", 1000.0, sensor=False)).run(u).y
    for name in SHIPPED[1:]:
        base = PlantConfig.for_profile("pea", 1000.0, sensor=False)
        y = Plant(PlantConfig.from_scenario(scenario_dir() / f"{name}.yaml", base)).run(u).y
        dev = np.max(np.abs(y - ref))
        assert 20e-9 < dev < 3e-6, name


def _write(tmp_path, text, name="s.yaml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_scenario_overrides_named_effects_and_applies_mismatch_and_seed(tmp_path):
    p = _write(tmp_path, "hyst_sim_scenario: 1\neffects:\n  delay: 4\n  noise: 0.0\n"
                         "mbw_factors: {zeta1: 1.2}\nseed: 9\n")
    base = PlantConfig.for_profile("pea", 1000.0).with_strengths(creep=0.01)
    cfg = PlantConfig.from_scenario(p, base)
    assert cfg.effects.strengths()["delay"] == 4 and cfg.effects.strengths()["noise"] == 0.0
    assert cfg.effects.strengths()["creep"] == 0.01             # not named: the base's setting stays
    assert cfg.mbw.zeta1 == pytest.approx(1.2 * pea_default().zeta1) and cfg.seed == 9


def test_numbers_yaml_1_1_leaves_as_text_and_whole_floats_read_as_the_node_reads_them(tmp_path):
    """``drift: 4e-9`` (PyYAML: a string) and ``delay: 3.0`` (the node takes 3.0) were refused."""
    s = load_scenario(_write(tmp_path, "hyst_sim_scenario: 1\neffects: {drift: 4e-9, delay: 3.0}\n"))
    eff = dict(s.effects)
    assert eff["drift"].strength == 4e-9 and eff["delay"].strength == 3 and isinstance(eff["delay"].strength, int)


@pytest.mark.parametrize("text, match", [
    ("effects: {creep: 0.01}\n", "not a hyst_sim scenario"),
    ("hyst_sim_scenario: 1\neffects: {backlash: 0.0123}\n", "unknown effect name"),
    ("hyst_sim_scenario: 1\neffects: {creep: 0.777}\n", "invalid or out of range"),
    ("hyst_sim_scenario: 1\neffects: {creep: {strength: 0.01, colour: 0.0123}}\n", "unknown setting"),
    ("hyst_sim_scenario: 1\nmbw_factors: {zeta9: 1.0}\n", "mbw_factors"),
    ("hyst_sim_scenario: 1\nextra: 1\n", "unknown top-level"),
    ("hyst_sim_scenario: 1\neffects: [1, 2\n", "cannot read"),
    # a non-finite shape put the reading at -1.8e10 m; a word meant two-sided; true was a 1 Hz resonance
    ("hyst_sim_scenario: 1\neffects: {drift: {strength: 4.0e-9, sine: .inf}}\n", "not a finite number"),
    ("hyst_sim_scenario: 1\neffects: {drift: {strength: 4.0e-9, walk: .nan}}\n", "not a finite number"),
    ("hyst_sim_scenario: 1\neffects: {saturation: {strength: 0.0123, two_sided: 'no'}}\n", "not true or false"),
    ("hyst_sim_scenario: 1\neffects: {dynamics: true}\n", "not a finite number"),
    ("hyst_sim_scenario: 1\neffects: {delay: 2.5}\n", "not a whole number"),
    ("hyst_sim_scenario: 1\nseed: true\n", "seed"),
    ("hyst_sim_scenario: 1\nmbw_factors: {zeta1: true}\n", "mbw_factors"),
])
def test_bad_scenarios_are_refused_without_echoing_values(tmp_path, text, match):
    p = _write(tmp_path, text)
    with pytest.raises(ScenarioError, match=match) as err:
        load_scenario(p)
    for secret in ("0.777", "0.0123", "backlash", "colour"):
        assert secret not in str(err.value)
    with pytest.raises(ScenarioError, match="no such"):
        load_scenario(tmp_path / "missing.yaml")


PARAMS = """/**:
  ros__parameters:
    model:
      base: mbw
      effects: []
      zeta1: 0.5
      zeta2: 1.0e-05
      psi1: 0.03
      psi2: 0.01
      alpha1: -0.04
      alpha2: -0.02
      delta1: 0.97
      delta2: 0.96
      offset: 1.0e-07
      u_scale: 15.0
      y_scale: 5.0e-06
      dt: 0.0005
"""


def test_params_file_sets_the_model_and_the_substeps(tmp_path):
    p = _write(tmp_path, PARAMS, "m.yaml")
    pf = load_params_file(p)
    assert pf.mbw.zeta1 == 0.5 and pf.mbw.offset == 1e-7 and pf.mbw.y_scale == 5e-6 and pf.dt == 5e-4
    cfg = PlantConfig.from_params_file(p, "pea", 1000.0)
    assert cfg.mbw_substeps == 2 and cfg.mbw == pf.mbw
    u = np.linspace(0, 150, 400)
    y = Plant(cfg.with_strengths(noise=0.0, quantization=0.0)).run(u).y
    np.testing.assert_array_equal(y, pf.mbw.simulate(np.repeat(u, 2))[1::2])  # ZOH at 2 kHz, read at 1 kHz
    assert PlantConfig.from_params_file(p, "pea", 2000.0).mbw_substeps == 1
    with pytest.raises(ConfigError, match="integer multiple"):
        PlantConfig.from_params_file(p, "pea", 3000.0)
    with pytest.raises(ScenarioError):
        load_params_file(tmp_path / "nope.yaml")
