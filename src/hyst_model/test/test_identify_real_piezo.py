"""Real data (../shared/data/piezo_150V_1Hz, Chandra et al. 2023, MIT): fit on the first three sine cycles after
t = 3.257 s, validate on the rest. A regression guard for the measured accuracy of the pure MBW, not a target:
measured 0.116 µm at 5 kHz (0.111 µm resampled to 2 kHz); the paper's sparse model reaches ~0.09 µm in-sample."""
from pathlib import Path

import numpy as np
import pytest

from hyst_model.identify import fit
from hyst_model.io import read_csv
from hyst_model.models import BASE_MODELS, data_config

DATA = Path(__file__).resolve().parents[4] / "shared" / "data" / "piezo_150V_1Hz" / "piezo_150V_1Hz.csv"


@pytest.mark.slow
@pytest.mark.skipif(not DATA.exists(), reason="shared data not present")
def test_mbw_on_real_piezo_first_three_cycles():
    rec = read_csv(DATA, columns="t_s,voltage_V,displacement_um", units="s,V,um").check()
    res = fit(BASE_MODELS["mbw"](data_config(rec.u, rec.y)), rec.t, rec.u, rec.y, split=(3.257, 6.257))
    assert res.rmse < 0.13e-6  # validation on t >= 6.257 s, about 3.7 unseen cycles
    bw = fit(BASE_MODELS["bw"](data_config(rec.u, rec.y)), rec.t, rec.u, rec.y, split=(3.257, 6.257))
    assert res.rmse < 0.7 * bw.rmse  # the rate terms matter on this stage (measured 0.116 vs 0.211 µm)
    # the remaining error is model structure, not noise: the sensor noise at rest is ~0.05 µm
    assert np.std(rec.y[rec.t < 3.2]) < 0.5 * res.rmse
