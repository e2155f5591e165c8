"""Randomised, seeded stage records for judging the diagnosis on data unlike the library's own scenarios.

Not the effect library: every physical effect here is written in a form that differs from
:mod:`hyst_model.effects` (log-law creep after steps, lags with static gain, sensor-side even nonlinearity, gain
kinks, one and two lightly damped modes, fractional input and output delays, exponential and periodic drift, hard
and soft saturation), plus effects outside the library (input dead zone, mid-record stiffness change) and a non-MBW
hysteresis truth (Prandtl–Ishlinskii); the sensor's noise white, with mains pickup, band-limited or quantised in
coarse steps. Other laws of the same physics (:mod:`.forms_alt`: power-law creep, an exponential sensor gain, a
mode with an antiresonance, a split latency, random-walk and accelerating drift, polynomial softening) make a
family of effect shapes the diagnosis was not developed on (``effect_forms="alt"``); other identification schedules
(:mod:`.excitation_alt`: decaying sines, staircases, trapezoids, multisines, bursts, over all or part of the range)
a family of excitations likewise (``excitations="alt"``). See :func:`generate_case` and
:func:`case_family`.
"""
from .cases import EFFECT_FORMS, EXCITATION_SETS, EXPECTED, KINDS, SENSORS, Case, case_family, generate_case
from .excitation import EXCITATIONS, excitation
from .excitation_alt import ALT_EXCITATIONS, excitation_alt
from .forms import FORMS

__all__ = ["Case", "generate_case", "case_family", "KINDS", "EXPECTED", "SENSORS", "EFFECT_FORMS", "FORMS",
           "EXCITATIONS", "excitation", "EXCITATION_SETS", "ALT_EXCITATIONS", "excitation_alt"]
