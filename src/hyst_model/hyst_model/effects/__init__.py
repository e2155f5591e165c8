"""Physical effects that extend a base hysteresis model: creep, asymmetry, delay, drift, saturation, rate,
dynamics — and any effect a user writes in their own file (``--effect-module``).

See :mod:`hyst_model.effects.base` for the Effect API and ``docs/examples/my_effect.py`` for an example.
"""
from .base import KINDS, ComposedModel, Effect, Inner
from .compose import EFFECTS, compose, effect_names, effects_data_config, register
from .user_module import load_effect_module

__all__ = ["EFFECTS", "Effect", "Inner", "ComposedModel", "KINDS", "compose", "effect_names", "effects_data_config",
           "register", "load_effect_module"]
