"""The band-limited noise part (``hyst excite --parts noise``) is an identification input: it keeps the simulated
stage off its stops, and the base MBW fitted to the record reaches the sensor noise, on both actuators."""
from __future__ import annotations

import pytest

from hyst_common.profiles import GMA_LIMITS, PEA_LIMITS
from hyst_control.excitation import ExcitationSpec, build_excitation


@pytest.mark.parametrize("profile", ["pea", "gma"])
def test_noise_excitation_keeps_the_stage_off_its_stops_and_fits(profile):
    from hyst_model.identify import fit
    from hyst_model.models import data_config
    from hyst_model.spec import build_model
    from hyst_sim.plant import Plant, PlantConfig
    lim = GMA_LIMITS if profile == "gma" else PEA_LIMITS
    rate = 2000.0
    for seed in range(3):
        ex = build_excitation(ExcitationSpec(v_min=lim.v_min, v_max=lim.v_max, slew_max=lim.slew_max, dt=1 / rate,
                                             parts=("steps", "noise"), n_steps=3, seconds=3.0, hold=0.1, seed=seed))
        r = Plant(PlantConfig.for_profile(profile, rate, sensor=True, seed=seed)).run(ex.u)
        assert not r.at_stop.any(), seed
        model = build_model("mbw", (), dict(data_config(r.u_applied, r.y), dt=1 / rate))
        res = fit(model, ex.t, r.u_applied, r.y, method="fast", split=0.25)
        assert res.rmse < 4e-9, (seed, res.rmse)  # 2 nm noise + 2 nm quantisation
