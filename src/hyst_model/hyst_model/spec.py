"""Build a model from its spec: a base model name, a list of effect names and fixed configuration.

This is the single place where a params file (``model.base``, ``model.effects``, ``model.<param>``) becomes a
:class:`~hyst_model.model.Model`. Base models are registered in :data:`hyst_model.models.BASE_MODELS`, effects in
:data:`hyst_model.effects.EFFECTS` (user effects join through ``--effect-module``).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

from .errors import DataError, EffectError, ParamsError
from .model import Model

__all__ = ["build_model", "parse_effect_config", "effect_settings"]


def build_model(base: str, effects: Sequence[str] = (), config: Mapping[str, object] | None = None) -> Model:
    """Return the model ``base`` (+ ``effects`` in order) with fixed configuration ``config``.

    Parameters
    ----------
    base : str
        Base model name, e.g. ``"mbw"`` or ``"bw"``.
    effects : sequence of str
        Effect names, e.g. ``("creep", "delay")``; empty for the base model alone.
    config : mapping
        Non-fitted configuration (``u_scale``, ``y_scale``, ``dt``, ...), as written by :meth:`Model.config`.

    Raises
    ------
    ParamsError
        Unknown base model.
    EffectError
        Unknown effect.
    """
    from .models import BASE_MODELS  # late: models import the core, not the other way round

    config = dict(config or {})
    try:
        factory = BASE_MODELS[base]
    except KeyError:
        raise ParamsError(f"unknown base model {base!r}; choose one of {', '.join(sorted(BASE_MODELS))}") from None
    model = factory(config)  # each factory picks the keys it needs and ignores the rest
    if not effects:
        return model
    try:
        from .effects import EFFECTS, compose
    except ImportError as err:
        raise EffectError(f"effects {', '.join(effects)} requested but no effects are available in this "
                          f"installation ({err})") from None
    unknown = [e for e in effects if e not in EFFECTS]
    if unknown:
        raise EffectError(f"unknown effect(s) {', '.join(map(repr, unknown))}; "
                          f"available: {', '.join(sorted(EFFECTS)) or 'none'}")
    try:
        return compose(model, list(effects), config)
    except KeyError as err:
        raise EffectError(f"unknown effect {err.args[0]!r}") from None


def parse_effect_config(items: Sequence[str], effects: Sequence[str], *,
                        names: tuple[str, str] = ("--config", "--effects")) -> dict:
    """``["dynamics.structure=feedback"]`` → ``{"dynamics.structure": "feedback"}`` (numbers as floats).

    Keys must belong to one of the listed effects (``<effect>.<key>``) and be one of its settings (what its
    :meth:`~hyst_model.effects.Effect.config` stores in a params file, in any of its variants): a mistyped key was
    silently ignored and the effect ran with its default (``drift.sid=sensor``). The effect itself checks the value.
    ``hyst fit --config``, ``hyst diagnose --config`` and the identification node's ``effect_config`` read their
    items here; ``names`` are the two settings as the messages call them (the node's ``effect_config``, ``effects``).

    Raises
    ------
    DataError
        An item that is not ``EFFECT.KEY=VALUE``, names an effect not listed, or a setting the effect has not.
    """
    from .effects.compose import effect_keys  # late: effects import the models
    out: dict = {}
    opt, eff = names
    for item in items:
        key, sep, value = item.partition("=")
        key, value = key.strip(), value.strip()
        name = key.split(".", 1)[0]
        if not sep or "." not in key or not value:
            raise DataError(f"{opt} needs EFFECT.KEY=VALUE, e.g. dynamics.structure=feedback, got {item!r}")
        if name not in effects:
            raise DataError(f"{opt} {key}: effect {name!r} is not in {eff} ({', '.join(effects) or 'none'})")
        keys = effect_keys(name)
        known = None if keys is None else keys[0]
        if known is not None and key.split(".", 1)[1] not in known:
            raise DataError(f"{opt} {key}: {name} has no setting {key.split('.', 1)[1]!r}; its settings are "
                            f"{', '.join(sorted(known)) or 'none'}")
        if key in out:  # the last one won silently
            raise DataError(f"{opt} {key} is given twice ({out[key]!r} and {value!r}); keep one")
        try:
            out[key] = float(value)
        except ValueError:
            out[key] = value
    return out


def effect_settings(effects: Sequence[str], t, u, y, split) -> dict:
    """Each effect's configuration from the samples a fit with ``split`` scores (:meth:`Effect.data_config`: the
    drift knots' span, the asymmetry's centres, creep's longest lag); ``hyst fit`` and the identification node
    merge it before the user's ``--config`` / ``effect_config``."""
    import numpy as np

    from .effects import effects_data_config
    from .identify.result import make_split
    scored = np.zeros(np.asarray(t).size, dtype=bool)
    scored[make_split(t, split).train_index()] = True
    return effects_data_config(list(effects), t, u, y, scored)
