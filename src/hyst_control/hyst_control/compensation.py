"""The controllers on the model the user identified: the base MBW law plus the effects as compensation.

A params file holds the base MBW and the effects the diagnosis named (``model.effects``). The control laws
(DPPC (4.11)–(4.14), DMRAC (5.22)–(5.25), the open-loop inverse) are one-step inversions of the base MBW (3.21);
the effects enter around them (:mod:`hyst_model.effects.online`):

* output-side effects with an inverse (creep, asymmetry, saturation) are inverted on the measurement and on the
  reference, so the law tracks the base model's output that makes the *measured* output follow the reference;
  a saturating stroke bounds the reachable reference (a target beyond it is held at the limit and counted);
* a transport delay is handled by a Smith predictor (the base model's undelayed minus delayed prediction is added
  to the measurement) and the reference is taken ``preview`` seconds ahead;
* a stage resonance after the hysteresis (series, held input) is inverted on the reference with the state the
  base model's prediction drives, and predicted out of the measurement (Smith); the stability check still judges
  the gains against the raw resonance (conservative: it holds if the compensation's model is off);
* where several effects predict (delay, resonance, and the static or creep effects next to them), they are
  predicted as one chain from the compensation's own base model (:attr:`Compensation.chain`): the measurement
  minus the whole model's prediction plus the base's, each resonance inverse driven by the prediction of what lies
  inside it, and creep outside a delay inverted with its lags at the previewed sample;
* the open-loop inverse reads no sensor: where every effect predicts, its effect states follow the model's own
  prediction for the commands it applied, through all of them as one chain (:attr:`Compensation.internal`), so
  it inverts its model exactly from the start;
* a drifting offset (input-independent, so nothing to invert) is estimated from the sensor by a disturbance
  observer and removed from measurement and reference, so the reading follows the reference (``drift.side:
  stage``, the default: the stage moves; the open-loop inverse reads no sensor and cannot follow it) — or from the
  measurement only, so the stage's position does (``sensor``: the sensor's offset drifts; the open-loop inverse
  needs no reading for it);
* an effect without a per-sample form (the feedback structure of dynamics; a user effect without
  :meth:`~hyst_model.effects.Effect.online`) is listed in
  :attr:`Compensation.unused` with the reason, which the node logs and puts on ``/diagnostics``: never dropped
  silently.

:class:`~hyst_control.compensated.Compensated` wraps any controller of this package with a
:class:`Compensation`; it speaks the same protocol (SI in and out), so the loop, the node and bumpless switching
use it unchanged.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from hyst_model.core import MBWParams

from .compensated import Compensated, wrap
from .errors import ConfigError

if TYPE_CHECKING:  # the effects load numba: imported where a plan is made
    from hyst_model.effects.online import Stepper

__all__ = ["Compensation", "Compensated", "plan_compensation", "from_params", "wrap", "effect_parameters"]


@dataclass
class Compensation:
    """The usable effects (innermost first) and the reasons for the others.

    Attributes
    ----------
    used : list of OnlineEffect
        Per-sample inverses, innermost first: the params file's order, with the effects that predict with the
        base model moved inward past linear ones (:func:`_base_first`; the model is the same).
    unused : dict
        Effect name → why the controllers cannot use it.
    """

    used: list = field(default_factory=list)
    unused: dict = field(default_factory=dict)
    #: The params file's effect order (reports use it; :attr:`used` may apply them in another, equivalent one).
    order: list = field(default_factory=list)
    #: The compensation's own per-sample base model (:class:`~hyst_model.effects.online.Stepper`): with it the
    #: Smith predictors and the effects inside them are predicted as one chain (:attr:`chain`).
    base: Stepper | None = None
    #: True for a law that reads no sensor (the open-loop inverse): its effect states follow the model's own
    #: prediction for the commands applied, where every effect predicts (:attr:`predicts_all`), instead of the
    #: aim it is handed. The aim is the model's output only where every command reached the stage as the law
    #: computed it: at a start from rest or a limited command, the inverse's creep lags took the aim's course for
    #: the stage's and stayed off it for seconds (a creep with a 317 Hz mode: 16.5 nm off its own model on a
    #: 1 Hz sine, 0.0 nm on the prediction).
    internal: bool = False

    @property
    def names(self) -> list[str]:
        """The effects used, in the params file's order."""
        rank = {n: i for i, n in enumerate(self.order)}
        return sorted((e.name for e in self.used), key=lambda n: rank.get(n, len(rank)))

    @property
    def preview(self) -> float:
        """Seconds of reference preview needed (the sum of the delays compensated)."""
        return float(sum(e.preview for e in self.used))

    @property
    def limited(self) -> int:
        """References that lay beyond a saturating stroke (held at the limit)."""
        return int(sum(getattr(e, "limited", 0) for e in self.used))

    def bounds(self) -> tuple[float, float]:
        """Reachable range of the measured output (m)."""
        lo, hi = -math.inf, math.inf
        for e in self.used:
            a, b = e.bounds()
            lo, hi = max(lo, a), min(hi, b)
        return lo, hi

    @property
    def chain(self) -> int:
        """How many innermost effects are predicted as one chain from :attr:`base`: the innermost run of
        predictive effects (:attr:`~hyst_model.effects.online.OnlineEffect.predictive`), if it holds a Smith
        predictor (:attr:`~hyst_model.effects.online.OnlineEffect.smith`); 0: none, each effect measures on its
        own. Effects outside the outermost Smith predictor still measure by their own inverse; the chain gives
        their targets the preview (creep's lags as they will be when the previewed sample arrives).

        A Smith predictor alone compares the measurement with its own effect on the bare base model: with a
        delay and a mode both on the base each took the other's share for model error (DPPC saturated on its own
        model), and a mode outside a bent loop (asymmetry) compared with the unbent prediction. The chain
        subtracts the whole model's predicted measurement instead, and drives each inverse's target state with the
        prediction of the structure inside it.
        """
        if self.base is None:
            return 0
        n, smith = 0, False
        for e in self.used:
            if not getattr(e, "predictive", False):
                break
            n += 1
            smith = smith or getattr(e, "smith", False)
        return n if smith else 0

    @property
    def predicts_all(self) -> bool:
        """True when the model's own measurement can be predicted through every effect used: a base model and
        each effect :attr:`~hyst_model.effects.online.OnlineEffect.predictive` (a drift with its offset
        estimate, which stays at zero where the law reads no sensor)."""
        return self.base is not None and all(getattr(e, "predictive", False) for e in self.used)

    def _own_model(self, sensor: bool = False) -> bool:
        """True when the effect states follow the model's own prediction through every effect (:attr:`internal`,
        no sensor reading, :attr:`predicts_all`); else only the innermost :attr:`chain` is predicted."""
        return self.internal and not sensor and self.predicts_all

    def _forward(self, m: int, z: float, u: float, start: bool) -> list[float]:
        """The model's predicted measurement at each of the ``m`` innermost effects' outputs, from the base
        model's ``z`` (their forward states advanced; ``start``: at rest first)."""
        w = z
        pred = []
        for i, e in enumerate(self.used[:m]):
            if start:
                e.start(z, u)
            z, w = e.forward(z, w, u, i == 0)
            pred.append(z)
        return pred

    def reset(self, y: float, u: float) -> float:
        """Start at rest at measured ``y`` under ``u``; returns the base model's output there."""
        x = y
        for e in reversed(self.used):
            e.reset(x, u)
            x = e.target(x, u)
        m = len(self.used) if self._own_model() else self.chain
        if m and self.base is not None:
            self._forward(m, self.base.reset(u), u, True)  # at rest: the stage's rest value through the effects
        return x

    def measure(self, y: float, u: float, sensor: bool = True) -> float:
        """Measured output → base model output (advances the effects' states).

        ``sensor`` False: ``y`` is the law's own aim, not a reading (open loop); observers (drift) are not fed.
        """
        own = self._own_model(sensor)
        # the law's own model: every effect predicted as one chain (an effect forwarded must not also measure:
        # its state would advance twice — a mode beside an inner drift, 228 nm off on a 30 Hz sine)
        n = len(self.used) if own else self.chain
        if n and self.base is not None:
            x_hat = self.base.step(u)
            pred = self._forward(n, x_hat, u, False)
            if own:
                y = pred[-1]  # the measurement the model predicts for the commands applied
        for e in reversed(self.used[n:]):
            y = e.measure(y, u)
        for i in range(n - 1, -1, -1):
            e = self.used[i]
            # a Smith predictor: the measurement minus the model through it plus the model inside it
            if e.smith:
                e.mismatch(y - pred[i])
                y = y - pred[i] + (pred[i - 1] if i else x_hat)
            else:
                y = e.measure(y, u)
        if sensor:
            for e in self.used:
                e.observe(y, u)
        return y

    def target(self, r: float, u: float) -> float:
        """Reference → base model output that produces it."""
        for e in reversed(self.used):
            r = e.target(r, u)
        return r

    def drift(self) -> tuple[float, bool] | None:
        """The drift observer's offset estimate (m) and whether the reading follows the reference (``drift.side:
        stage``) — None without a drift effect."""
        for e in self.used:
            if e.name == "drift" and hasattr(e, "offset"):
                return float(e.offset), bool(getattr(e, "follow_reading", True))
        return None

    @property
    def sensor_only(self) -> list[str]:
        """Effects estimated from the sensor (drift): the feedback laws use them, the open-loop inverse cannot."""
        return [e.name for e in self.used if e.needs_sensor]

    def _blind(self, algorithm: str | None) -> list[str]:
        """Effects ``algorithm`` cannot use because it reads no sensor (the open-loop inverse)."""
        return self.sensor_only if algorithm == "open_loop" else []

    def compensated(self, algorithm: str | None = None) -> list[str]:
        """The effects ``algorithm`` compensates (open loop: not the sensor-only ones), in the file's order."""
        blind = self._blind(algorithm)
        return [n for n in self.names if n not in blind]

    def not_compensated(self, algorithm: str | None = None) -> dict[str, str]:
        """Effect → why ``algorithm`` does not compensate it."""
        return {**self.unused, **{n: "estimated from the sensor, which the open-loop inverse does not read"
                                  for n in self._blind(algorithm)}}

    def describe(self, algorithm: str | None = None) -> str:
        """One sentence for logs and /diagnostics ('' when there is nothing to say); ``algorithm`` "open_loop"
        lists the sensor-only effects as not compensated."""
        parts = []
        names = self.compensated(algorithm)
        if names:
            parts.append("compensating " + ", ".join(names)
                         + (f" (reference previewed {self.preview * 1e3:.3g} ms)" if self.preview > 0 else ""))
        unused = self.not_compensated(algorithm)
        if unused:
            parts.append("not compensated: " + "; ".join(f"{k}: {v}" for k, v in unused.items()))
        return "; ".join(parts)


def plan_compensation(model: MBWParams, effects: Sequence[str], values: Mapping[str, float],
                      config: Mapping[str, object] | None = None, dt: float | None = None) -> Compensation:
    """Build the compensation for ``model`` + ``effects`` with fitted ``values`` (``"creep.gain"`` → value).

    Parameters
    ----------
    model : MBWParams
        The base model the law inverts.
    effects : sequence of str
        Effect names in the params file's order (first innermost).
    values : mapping
        Effect parameters, dotted (``creep.gain``), SI. Every parameter of every effect must be present.
    config : mapping, optional
        Effect configuration (``asymmetry.u_c``, ``delay.side``, ...), as in the params file.
    dt : float, optional
        Loop period (s); default ``config["dt"]``.

    Raises
    ------
    ConfigError
        Unknown effect, a missing parameter, or an effect whose inverse does not exist at these values.
    """
    from hyst_model.effects.online import MBWStepper  # effects load numba; only when used
    from hyst_model.errors import HystError
    from hyst_model.spec import build_model

    from hyst_model.effects import EFFECTS
    from hyst_model.effects.base import ComposedModel

    comp = Compensation()
    effects = order = [str(e) for e in effects]
    for name in effects:
        if name not in EFFECTS:  # a user effect whose module this process did not load
            comp.unused[name] = "unknown to this process (a user effect?): the controllers cannot use it"
    effects = [e for e in effects if e in EFFECTS]
    if not effects:
        return comp
    cfg = {k: v for k, v in dict(config or {}).items()}
    cfg.update(u_scale=model.u_scale, y_scale=model.y_scale, offset=model.offset)
    if dt is not None:
        cfg["dt"] = float(dt)
    try:
        composed = build_model("mbw", effects, cfg)
    except (HystError, ValueError, TypeError) as err:
        raise ConfigError(f"cannot build the model's effects {', '.join(effects)}: {err}") from err
    if not isinstance(composed, ComposedModel):  # build_model composes whenever there are effects
        raise ConfigError(f"the model with effects {', '.join(effects)} is not a composed model")
    for e in _base_first(list(composed.effects)):
        names = [p.name for p in e.params()]
        # a parameter added after the file was written reads as the value that keeps the older behaviour
        values = {**{f"{e.name}.{k}": v for k, v in e.legacy_values().items()}, **values}
        missing = [n for n in names if f"{e.name}.{n}" not in values]
        if missing:
            raise ConfigError(f"effect {e.name}: parameter(s) {', '.join(e.name + '.' + n for n in missing)} "
                              "missing from the model")
        # an array, as Effect.online takes it: a list broke (or silently repeated) array arithmetic on theta
        theta = np.array([float(values[f"{e.name}.{n}"]) for n in names], dtype=np.float64)
        for p, v in zip(e.params(), theta):
            if not (math.isfinite(v) and p.lower <= v <= p.upper):
                raise ConfigError(f"effect {e.name}: {e.name}.{p.name} = {v:g} {p.unit} lies outside "
                                  f"[{p.lower:g}, {p.upper:g}]")
        try:
            on = e.online(theta, base=lambda: MBWStepper(model))
        except (ValueError, ArithmeticError) as err:
            raise ConfigError(f"effect {e.name} cannot be inverted for control: {err}") from err
        except Exception as err:  # a user effect's online() failing: name it, do not crash the controller
            raise ConfigError(f"effect {e.name}: its online() failed ({type(err).__name__}: {err})") from err
        if on is None:
            comp.unused[e.name] = getattr(e, "online_note", "no per-sample form")
        else:
            on.name = e.name
            comp.used.append(on)
    comp.unused = {e: comp.unused[e] for e in order if e in comp.unused}  # in the params file's order
    comp.order = list(order)
    comp.base = MBWStepper(model)
    return comp


def _base_first(effects: list) -> list:
    """``effects`` (innermost first) with each one whose per-sample form predicts with the base model
    (:attr:`Effect.on_base`: delay, series resonance) moved inward past linear ones (:attr:`Effect.linear`) and
    past a drift (:func:`_passable`).

    Linear time-invariant operators commute, so the order changes nothing in the model; but such a form is exact
    only directly on the base: a resonance identified outside creep was inverted with its state driven by the
    base instead of the creeping output (300 nm off its own model on a 1 Hz sine). Past a nonlinear effect
    (asymmetry, saturation) nothing moves: the inverse there stays approximate.
    """
    out = list(effects)
    for i in range(len(out)):
        e = out[i]
        if not getattr(e, "on_base", False):
            continue
        j = i
        while j > 0 and _passable(out[j - 1]):
            j -= 1
        out[j:i + 1] = [e] + out[j:i]
    return out


def _passable(e) -> bool:
    """An effect a base-predicting one may move inward past: a linear one, or an offset that is a function of
    time alone (drift), which the controllers estimate from the sensor wherever it sits (an inner drift left a
    fractional input delay predicting by interpolating the drifting output, and the observer took the start's
    transient for drift: DMRAC 870 nm off its own model on a 30 Hz sine)."""
    return (getattr(e, "linear", False) or getattr(e, "of_time", False)) and not getattr(e, "on_base", False)


def effect_parameters(dt: float, u_scale: float, y_scale: float) -> dict[str, tuple[object, str]]:
    """Every built-in effect's parameters and configuration keys as node parameters.

    Returns ``{"creep.gain": (default, description), "delay.side": ("input", ...), ...}``: the identity values
    (an effect at its defaults changes nothing), so a node can declare them all and take any params file or push.
    Effects with several configurations (dynamics' structures) contribute the union of their parameters.
    """
    from hyst_model.effects import EFFECTS

    base = {"dt": dt, "u_scale": u_scale, "y_scale": y_scale}
    out: dict[str, tuple[object, str]] = {}
    for name in sorted(EFFECTS):
        cls = EFFECTS[name]
        # the plain configuration first: a key's default must be what a params file without it means
        variants = [{}] + (list(cls.variants()) if hasattr(cls, "variants") else [])
        for var in variants:
            e = cls({**base, **var})
            for p in e.params():
                out.setdefault(f"{name}.{p.name}", (float(p.default), f"{name}: {p.doc} ({p.unit or '-'})"))
            for k, v in e.config().items():
                out.setdefault(f"{name}.{k}", (v, f"{name} configuration (params file)"))
    return out


def from_params(spec, dt: float | None = None) -> tuple[MBWParams, Compensation]:
    """The base MBW and the compensation of a params file (:class:`hyst_model.io.params_file.ParamsSpec`).

    Raises
    ------
    ConfigError
        Base other than ``mbw``, missing base parameters or scales, or an effect that cannot be planned.
    """
    from hyst_model.core import PARAM_NAMES

    if spec.base != "mbw":
        raise ConfigError(f"the controllers invert the MBW model: model.base must be 'mbw', not {spec.base!r}")
    vals, cfg = dict(spec.values), dict(spec.config)
    missing = [n for n in PARAM_NAMES if n not in vals] + [k for k in ("u_scale", "y_scale") if k not in cfg]
    if missing:
        raise ConfigError(f"params lack {', '.join(missing)}")
    model = MBWParams(**{n: float(vals[n]) for n in PARAM_NAMES}, u_scale=float(cfg["u_scale"]),
                      y_scale=float(cfg["y_scale"]), offset=float(vals.get("offset", 0.0)))
    mdt = cfg.get("dt")
    return model, plan_compensation(model, spec.effects, vals, cfg, dt if dt is not None else mdt)
