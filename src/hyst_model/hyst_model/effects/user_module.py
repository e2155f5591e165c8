"""Load a user's own effects from a Python file (``hyst fit/diagnose/compare --effect-module path.py``).

The file defines one or more subclasses of :class:`hyst_model.effects.Effect` (see
``docs/examples/my_effect.py``). Each becomes a registered effect, usable everywhere a built-in is: in
``--effects``, in params files (``model.effects``) and as a diagnose candidate.
"""
from __future__ import annotations

import hashlib
import importlib.util
import sys
from pathlib import Path
from typing import cast

import numpy as np

from ..errors import EffectError
from ..model import Model
from .base import Effect
from .compose import register

__all__ = ["load_effect_module"]


def load_effect_module(path: str | Path) -> list[str]:
    """Import ``path`` and register every Effect subclass it defines; return their names.

    Each class is checked before it is registered: it must have a name, a valid kind, parameters with
    ``lower <= default <= upper``, and must simulate a short record through an identity base to finite values.

    Raises
    ------
    EffectError
        Missing file, a syntax or import error in it, no Effect subclass, or an effect that fails the check —
        always one message naming the file and the problem.
    """
    p = Path(path)
    if p.is_dir():
        raise EffectError(f"effect module {p} is a directory; give the .py file that defines the Effect")
    if not p.is_file():
        raise EffectError(f"effect module {p}: no such file")
    if p.suffix != ".py":
        raise EffectError(f"effect module {p}: expected a .py file")
    modname = "hyst_user_effect_" + hashlib.sha1(str(p.resolve()).encode()).hexdigest()[:12]
    try:
        spec = importlib.util.spec_from_file_location(modname, p)
        if spec is None or spec.loader is None:
            raise ImportError("not importable")
        mod = importlib.util.module_from_spec(spec)
        sys.modules[modname] = mod
        spec.loader.exec_module(mod)
    except SyntaxError as err:
        sys.modules.pop(modname, None)
        raise EffectError(f"effect module {p}: syntax error at line {err.lineno}: {err.msg}") from err
    except Exception as err:  # anything a user file raises at import is "broken module"
        sys.modules.pop(modname, None)
        raise EffectError(f"effect module {p}: import failed: {type(err).__name__}: {err}") from err
    except SystemExit as err:  # sys.exit() at import ended hyst fit with exit 0 and no output at all
        sys.modules.pop(modname, None)
        raise EffectError(f"effect module {p}: import failed: it called sys.exit({err.code!r})") from err
    classes = [obj for obj in vars(mod).values()
               if isinstance(obj, type) and issubclass(obj, Effect) and obj is not Effect
               and obj.__module__ == modname]
    if not classes:
        raise EffectError(f"effect module {p}: defines no subclass of hyst_model.effects.Effect")
    from . import EFFECTS
    names = []
    for cls in classes:
        have = EFFECTS.get(cls.name)  # an Effect subclass always has one (Effect.name at least)
        if have is not None and have.__module__.startswith("hyst_model.effects."):
            # a user file must not silently replace a built-in (its params files would change meaning)
            raise EffectError(f"effect module {p}: {cls.__name__} is named {cls.name!r}, a built-in effect; "
                              "give it another name")
        _check(p, cls)
        register(_guarded(cls, p), replace=True)
        names.append(cls.name)
    return names


#: Methods of a user effect that run during fits and simulations; an exception there is reported by name.
_GUARDED = ("params", "apply", "input", "output", "start")


def _guarded(cls: type[Effect], path: Path) -> type[Effect]:
    """A subclass whose fitting-time methods turn any exception into one :class:`EffectError` naming the effect,
    the method and the file — a user effect that fails only deep inside a long run (its 5th call, long inputs)
    is then one line (``hyst fit``, ``simulate``, ``compare``: exit 2; ``diagnose``: that candidate's fit failed,
    with this sentence in its evidence), never a traceback."""
    def wrap(method_name: str):
        orig = getattr(cls, method_name)

        def guarded(self, *args, **kwargs):
            try:
                return orig(self, *args, **kwargs)
            except EffectError:
                raise
            except Exception as err:  # the user's code: report it, do not crash the run
                raise EffectError(f"user effect {cls.name!r} ({path.name}) failed in {method_name}(): "
                                  f"{type(err).__name__}: {err}") from err
        guarded.__name__ = method_name
        guarded.__doc__ = orig.__doc__
        return guarded

    body = {m: wrap(m) for m in _GUARDED}
    body.update(__module__=cls.__module__, __doc__=cls.__doc__, __qualname__=cls.__qualname__)
    return type(cls.__name__, (cls,), body)


class _Identity:
    """A stand-in base model for the check: output = input (1 m per V)."""

    name = "identity"

    def params(self):
        return ()

    def config(self):
        return {}

    def simulate(self, theta, t, u):
        return np.asarray(u, dtype=np.float64).copy()


def _check(path: Path, cls: type[Effect]) -> None:
    from .base import Inner
    name = getattr(cls, "name", "")
    where = f"effect module {path}: class {cls.__name__}"
    if not isinstance(name, str) or not name.isidentifier() or name == "effect":
        raise EffectError(f"{where} needs a class attribute name = '<identifier>'")
    if cls.kind not in ("input", "output", "wrap", "base"):
        raise EffectError(f"{where}: kind must be input, output, wrap or base, not {cls.kind!r}")
    try:
        eff = cls({"dt": 1e-3, "u_scale": 1.0, "y_scale": 1.0})
        ps = eff.params()
        for q in ps:
            if not (q.lower <= q.default <= q.upper):
                raise ValueError(f"parameter {q.name}: default {q.default} outside [{q.lower}, {q.upper}]")
        theta = np.array([q.default for q in ps], dtype=np.float64)
        t = np.arange(200) * 1e-3
        u = np.sin(2 * np.pi * 5 * t)
        if cls.kind == "base":  # replaces a real base model's recursion; checked when composed
            return
        base = _Identity()
        # the stand-in offers the Model methods the check's effects (not kind base) read: name, params, config,
        # simulate
        inner = Inner(lambda tt, uu: base.simulate((), tt, uu), cast(Model, base), np.empty(0))
        y = eff.apply(theta, t, u, inner)
        y = np.asarray(y, dtype=np.float64)
        if y.shape != u.shape or not np.all(np.isfinite(y)):
            raise ValueError(f"simulate returned shape {y.shape} / non-finite values for its default parameters")
        score, text = eff.signature(t, u, np.zeros_like(u), 1e-3)
        float(score), str(text)
    except EffectError:
        raise
    except Exception as err:
        raise EffectError(f"{where} fails its self-check: {type(err).__name__}: {err}") from err
