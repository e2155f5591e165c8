"""The PID's default gains on another stage (hyst_control.pid.gains_for): the loop gain they were tuned for."""
from hyst_control.pid import PIDGains, gains_for, static_gain
from hyst_model.core import pea_default


def test_default_gains_move_to_another_stage_by_its_static_gain():
    """The embedded stage keeps the defaults exactly; a stage of ten times its µm/V gets a tenth."""
    m = pea_default()
    assert abs(static_gain(m, 0.0, 150.0) - 0.2e-6) < 0.01e-6                  # ≈ 0.2 µm/V (the docstring's)
    assert gains_for(m, 0.0, 150.0) == PIDGains()
    g = gains_for(m.replace(y_scale=10 * m.y_scale), 0.0, 150.0)
    assert abs(g.kp / PIDGains().kp - 0.1) < 1e-12 and abs(g.ki / PIDGains().ki - 0.1) < 1e-12
    assert g.t_track == PIDGains().t_track                                     # time constants are not gains
    assert gains_for(m.replace(y_scale=-m.y_scale), 0.0, 150.0) == PIDGains()  # no positive gain: unchanged
