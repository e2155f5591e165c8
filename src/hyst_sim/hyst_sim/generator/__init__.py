"""Randomised, seeded stage records for judging the diagnosis on data unlike the library's own scenarios.

Not the effect library: every physical effect here is written in a form that differs from
:mod:`hyst_model.effects` (log-law creep after steps, lags with static gain, sensor-side even nonlinearity, gain
kinks, one and two lightly damped modes, fractional input and output delays, exponential and periodic drift, hard
and soft saturation), plus effects outside the library (input dead zone, mid-record stiffness change) and a non-MBW
hysteresis truth (Prandtl–Ishlinskii); the sensor's noise white, with mains pickup or band-limited. See
:func:`generate_case` and :func:`case_family`.
"""
from .cases import EXPECTED, KINDS, SENSORS, Case, case_family, generate_case
from .excitation import EXCITATIONS, excitation
from .forms import FORMS

__all__ = ["Case", "generate_case", "case_family", "KINDS", "EXPECTED", "SENSORS", "FORMS", "EXCITATIONS",
           "excitation"]
