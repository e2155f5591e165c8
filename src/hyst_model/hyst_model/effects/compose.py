"""Compose a base model with named effects; the effect registry and user effect modules.

:data:`EFFECTS` maps effect names to classes. Built-ins register here; H5b's ``dynamics`` joins when its module is
importable; a user's ``--effect-module path.py`` adds its :class:`~hyst_model.effects.base.Effect` subclasses
through :func:`register` (see :mod:`hyst_model.effects.user_module`).
"""
from __future__ import annotations

import importlib
from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..errors import EffectError
from ..model import Model, Param
from .base import ComposedModel, Effect, Inner

__all__ = ["EFFECTS", "compose", "register", "effect_names", "Frozen", "effects_data_config", "effect_keys",
           "around_effects"]

#: name → Effect subclass. Filled by :func:`_load_builtins` at import and by :func:`register`.
EFFECTS: dict[str, type[Effect]] = {}

_BUILTIN_MODULES = ("creep", "asymmetry", "delay", "drift", "saturation", "rate", "dynamics")


def register(cls: type[Effect], *, replace: bool = False) -> type[Effect]:
    """Add an effect class to :data:`EFFECTS` (usable as a decorator).

    Raises
    ------
    EffectError
        ``cls`` is not an Effect subclass, has no usable name, or the name is taken (unless ``replace``).
    """
    if not (isinstance(cls, type) and issubclass(cls, Effect)) or cls is Effect:
        raise EffectError(f"{cls!r} is not a subclass of hyst_model.effects.Effect")
    name = getattr(cls, "name", "")
    if not isinstance(name, str) or not name.isidentifier() or name == "effect":
        raise EffectError(f"effect class {cls.__name__} needs a class attribute name = '<identifier>'")
    if name in EFFECTS and EFFECTS[name] is not cls and not replace:
        raise EffectError(f"an effect called {name!r} already exists ({EFFECTS[name].__module__}); rename yours")
    if cls.kind not in ("input", "output", "wrap", "base"):
        raise EffectError(f"effect {name!r}: kind must be input, output, wrap or base, not {cls.kind!r}")
    EFFECTS[name] = cls
    return cls


def effect_names() -> list[str]:
    """Registered effect names, sorted."""
    return sorted(EFFECTS)


def compose(model: Model, names: Sequence[str | Effect],
            config: Mapping[str, object] | None = None) -> ComposedModel:
    """Extend ``model`` by the named effects, first name innermost; returns a :class:`ComposedModel`.

    Parameters
    ----------
    model : Model
        Base model (or an already composed model, which is extended further).
    names : sequence of str or Effect
        Effect names from :data:`EFFECTS` (or ready Effect instances).
    config : mapping, optional
        Fixed configuration (``dt``, ``u_scale``, ``y_scale``, ``<effect>.<key>`` ...); the base model's own
        config fills what is missing.

    Raises
    ------
    EffectError
        Unknown name, an effect listed twice, two effects modelling the same physics, or an effect that does
        not apply to this base model.
    """
    cfg: dict[str, object] = dict(model.config())
    cfg.update(dict(config or {}))
    effects: list[Effect] = []
    for n in names:
        if isinstance(n, Effect):
            effects.append(n)
            continue
        key = str(n).strip()
        if key not in EFFECTS:
            raise EffectError(f"unknown effect {key!r}; choose from {', '.join(effect_names())} "
                              "(or add your own with --effect-module)")
        try:
            effects.append(EFFECTS[key](cfg))
        except EffectError:
            raise
        except Exception as err:  # a user effect's constructor may fail in any way
            raise EffectError(f"effect {key!r} cannot be constructed: {type(err).__name__}: {err}") from err
    return ComposedModel(model, effects)


def _load_builtins() -> None:
    for mod in _BUILTIN_MODULES:
        try:
            m = importlib.import_module(f"{__package__}.{mod}")
        except ImportError:  # e.g. dynamics not written yet: the rest must keep working
            continue
        except Exception:  # a broken sibling module must not take every effect down
            if mod in ("creep", "asymmetry", "delay", "drift", "saturation", "rate"):
                raise
            continue
        for obj in vars(m).values():
            if isinstance(obj, type) and issubclass(obj, Effect) and obj is not Effect \
                    and obj.__module__ == m.__name__ and getattr(obj, "name", "effect") != "effect":
                register(obj, replace=True)


_load_builtins()


class Frozen(Effect):
    """An effect with its parameters held fixed (it then has none to fit).

    Used to refit the base model *around* an effect at its data-driven start: a base fitted without the effect
    is distorted by it (e.g. its δ terms imitate a delay), and a joint refit from there can stall in that
    basin. Fitting the base with the effect frozen first, then everything jointly, avoids that.
    """

    def __init__(self, effect: Effect, theta: ArrayLike):
        super().__init__(getattr(effect, "_config", {}))
        self.effect = effect
        self.theta = np.asarray(theta, dtype=np.float64)
        self.name = effect.name
        self.kind = effect.kind
        self.conflicts = effect.conflicts
        self.bases = effect.bases
        self.summary = effect.summary
        self.physics = effect.physics

    def params(self) -> tuple[Param, ...]:
        return ()

    def config(self) -> dict[str, float | str]:
        return self.effect.config()

    def apply(self, theta: np.ndarray, t: np.ndarray, u: np.ndarray, inner: Inner) -> np.ndarray:
        return self.effect.apply(self.theta, t, u, inner)

    def check(self, base: Model, others: Sequence[Effect]) -> None:
        self.effect.check(base, others)


def effects_data_config(names: Sequence[str], t: np.ndarray, u: np.ndarray, y: np.ndarray,
                        scored: np.ndarray) -> dict:
    """The configuration each named effect takes from the record (:meth:`Effect.data_config`), merged."""
    out: dict = {}
    for n in names:
        if n not in EFFECTS:
            raise EffectError(f"unknown effect {n!r}; choose from {', '.join(sorted(EFFECTS))}")
        out.update(EFFECTS[n].data_config(t, u, y, scored) or {})
    return out


def effect_keys(name: str, settings_in: Mapping[str, object] | None = None
                ) -> tuple[frozenset[str], frozenset[str]] | None:
    """The keys (local names) effect ``name`` reads from a params file, over all its variants: its settings
    (:meth:`Effect.config`) and its parameters (with :meth:`Effect.legacy_values`). None for an effect this
    process does not know, or whose constructor needs more than the scales (a user effect): its keys are then not
    checked (``--config``, :func:`hyst_model.io.params_file.read_params`).

    ``settings_in``: the file's own settings (dotted keys), which fix what is not a variant — a drift of 3 knots
    has no ``c4`` (a hand-lowered ``knots`` left fitted offsets in the file, read and never used)."""
    cls = EFFECTS.get(name)
    if cls is None:
        return None
    own = {k: v for k, v in (settings_in or {}).items() if str(k).startswith(f"{name}.")}
    base = {"dt": 1e-3, "u_scale": 1.0, "y_scale": 1e-6, **own}
    settings: set[str] = set()
    params: set[str] = set()
    try:
        for var in [{}] + list(cls.variants() if hasattr(cls, "variants") else []):
            e = cls({**base, **var})
            settings |= set(e.config())
            params |= {p.name for p in e.params()} | set(e.legacy_values())
    except Exception:  # noqa: BLE001 - a user effect's constructor: its keys are then not checked
        return None
    return frozenset(settings), frozenset(params)


def around_effects(m: ComposedModel, theta: np.ndarray, t, u, y, record: bool = False
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The input and output the base of ``m`` sees at ``theta``: ``u`` through the input-side effects, and ``y``
    with the outermost output-side effects undone as far as they can be (:meth:`Effect.undo_output`, outermost
    first, stopping at the first that cannot). The same objects when no effect changes them.

    A base fitted to the record as it is has imitated the effects (its δ terms lag like a delay on either side),
    and a joint fit from there stays in that basin: the fitters refit the base on these first
    (:func:`hyst_model.diagnose.refit.refit`, :meth:`hyst_model.identify.fast.FastFit._around`).

    An effect whose start is read off the base's own residual but that the base absorbs (a drift:
    :attr:`Effect.undo_at_own_start` False) is undone only at a start read off the record alone (``record``:
    :meth:`Effect.record_start`): its residual start is what the base left, and refitting the base around it
    only moves the base off the point it was fitted to.
    """
    parts = m.split(theta)[1]
    uu = u
    for e, te in zip(m.effects, parts):
        if e.kind == "input":
            uu = e.input(te, t, uu)
    yy = y
    for e, te in reversed(list(zip(m.effects, parts))):
        if e.kind == "input":
            continue
        if e.kind != "output":
            break
        back = e.undo_output(te, t, u, yy) if record or e.undo_at_own_start else None
        if back is None:
            break
        yy = np.asarray(back, dtype=np.float64)
    return uu, yy
