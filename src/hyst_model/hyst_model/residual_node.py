"""hyst_residual_node: the model's prediction and residual next to ``/stage/state``, live or from a bag replay.

Subscribes ``/stage/state`` (``effort[0]`` applied V, ``position[0]`` measured m) and runs the model of a params
file on the applied voltage, sample by sample; publishes

* ``/model/prediction`` — ``position[0]`` = model output (m),
* ``/model/residual`` — ``position[0]`` = measured − model (m),

both ``sensor_msgs/JointState`` with ``name=['stage']`` and ``header.stamp`` = the stamp of the state sample, so
PlotJuggler or Foxglove plot them on the same time axis as the stage.

Run::

    hyst_residual_node --ros-args --params-file stage.yaml

Parameters: the params file's ``model.*`` (``model.base``, ``model.effects``, every model parameter and its
configuration, read like the controller node does) plus

* ``reset_gap`` (s): a jump in the state stamps larger than this (or backwards, e.g. a bag replay restarting)
  restarts the model at rest under the current input;
* a state whose applied voltage is not finite or beyond twice the model's range is ignored and counted; the
  counts go to ``/diagnostics`` every second (WARN while states are being ignored); without a params file the
  node refuses to start (the default model speaks model units);
* ``history`` (s) and ``batch`` (samples): only for models without a per-sample form (base + effects, PI): the
  model is re-simulated over the last ``history`` seconds every ``batch`` samples and the new samples' predictions
  are published then (stamped with their own state stamps). That is exact while the record is shorter than
  ``history`` and an approximation afterwards (memory older than ``history`` is forgotten).

The MBW/BW base models run exactly per sample through :func:`hyst_model.core.mbw_step` (thesis (3.21)), starting at
rest under the first input (:func:`hyst_model.core.mbw_rest_state`). Parameters can be changed at run time (e.g.
by the identification node); a new model is validated in the on-set callback (every value finite, the model
simulates a short record to finite values) and applied by swapping a frozen config, restarting at rest.
"""
from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.exceptions import ParameterUninitializedException
from sensor_msgs.msg import JointState

from .core import mbw_rest_state, mbw_step
from .errors import HystError
from .model import MBWModel, Model
from hyst_common.node import AtomicParametersNode, diagnostic_array, diagnostic_status, fp_range, int_range, run_node
from .spec import build_model

__all__ = ["ResidualNode", "ResidualSettings", "main"]

USAGE = (
    'hyst_residual_node: run the model from a params file next to /stage/state and publish /model/prediction and\n'
    '/model/residual (m), stamped like the state sample.\n'
    '\n'
    'usage: hyst_residual_node --ros-args --params-file stage.yaml [-p reset_gap:=0.5 ...]'
)


@dataclass(frozen=True)
class ResidualSettings:
    """Everything the node runs with, swapped as a whole when parameters change."""

    model: Model
    theta: np.ndarray = field(compare=False)
    reset_gap: float
    history: float
    batch: int
    #: A voltage beyond ±this (V) is taken for a corrupt sample and not run: twice the model's full range (its
    #: fitting convention is ±10 units of ``u_scale``); one 1e4 V sample sent the prediction to −1 cm for 200 samples.
    u_max: float = math.inf
    #: A reading outside this range (m) is taken for a corrupt sample: it is not compared (no residual is published
    #: for it) and counted. The model's output over the full-range test sine widened by its span at each end (as
    #: the controller judges states); a 1e300 m reading was published as a 1e300 m residual.
    y_range: tuple[float, float] = (-math.inf, math.inf)

    @property
    def streaming(self) -> bool:
        """True when the model runs exactly per sample (the MBW/BW base without effects)."""
        return isinstance(self.model, MBWModel)


def _stamp(msg: JointState) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


class ResidualNode(AtomicParametersNode):
    """Publishes model prediction and residual for every ``/stage/state`` sample."""

    def __init__(self, **kwargs):
        super().__init__("hyst_residual", **kwargs)
        self._model_keys: set[str] = set()
        self._numeric_keys: set[str] = set()  # model keys declared with a number: a bool or word is refused
        if not {"model.u_scale", "model.y_scale"} & set(self._parameter_overrides):
            # the default model's units are 1 V and 1 m per unit: it predicted 120 m at 75 V
            raise HystError("no model given: start with the params file whose model to run (--ros-args "
                            "--params-file stage.yaml, as hyst fit or hyst diagnose --out write it)")
        self._declare()
        self._settings = self._read()
        self._reset()
        self._n = dict.fromkeys(("states", "bad_states", "bad_readings", "published", "resets"), 0)
        self._n_seen = dict(self._n)
        self.add_on_set_parameters_callback(self._on_set)
        self.add_post_set_parameters_callback(self._after_set)
        self._pred_pub = self.create_publisher(JointState, "/model/prediction", 100)
        self._res_pub = self.create_publisher(JointState, "/model/residual", 100)
        self.create_subscription(JointState, "/stage/state", self._on_state, 100)
        self._diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_timer(1.0, self._publish_diagnostics)
        s = self._settings
        self.get_logger().info(f"residual node ready: model {s.model.name} "
                               f"({'per sample' if s.streaming else f'batches of {s.batch}'})")

    # Parameters -----------------------------------------------------------------------------------------
    def _declare(self) -> None:
        d = self.declare_parameter
        d("reset_gap", 0.5, ParameterDescriptor(
            description="restart the model at rest after a stamp gap longer than this (s) or a stamp going back",
            floating_point_range=fp_range(1e-4, 3600.0)))
        d("history", 30.0, ParameterDescriptor(
            description="re-simulation window (s) for models without a per-sample form",
            floating_point_range=fp_range(0.1, 3600.0)))
        d("batch", 100, ParameterDescriptor(
            description="samples per re-simulation for models without a per-sample form",
            integer_range=int_range(1, 100_000)))
        d("model.base", "mbw", ParameterDescriptor(description="base model (params file model.base)"))
        d("model.effects", [""],
          ParameterDescriptor(description="effects in order (params file model.effects); empty = base only"))
        # The model's keys depend on base + effects (and effect configuration such as dynamics.structure):
        # declare the configuration keys first, then every parameter of the model they build.
        base, effects = self._spec_names({})
        probe = build_model(base, effects, {})
        for key in sorted(probe.config()):
            self._declare_model_key(key, probe.config()[key], "configuration (not fitted)")
        model = build_model(base, effects, self._config({}))
        for key in sorted(model.config()):
            self._declare_model_key(key, model.config()[key], "configuration (not fitted)")
        for p in model.params():
            self._declare_model_key(p.name, p.default, f"{p.doc} [{p.unit or '-'}]")
        self._declare_model_key("dt", 0.0, "sample time the model was fitted at (s; informative)")

    def _declare_model_key(self, key: str, default, doc: str) -> None:
        name = f"model.{key}"
        if name in self._model_keys or self.has_parameter(name):
            return
        self._model_keys.add(name)
        value = float(default) if isinstance(default, (int, float)) else str(default)
        if isinstance(value, float):
            self._numeric_keys.add(name)
        # dynamic typing: a hand-written params file may say 20 where the model says 20.0
        self.declare_parameter(name, value, ParameterDescriptor(description=doc, dynamic_typing=True))

    def _get(self, name: str, changes: dict):
        if name in changes:
            return changes[name]
        try:
            return self.get_parameter(name).value
        except ParameterUninitializedException:  # e.g. 'effects: []' — rcl's YAML parser drops empty lists
            return None

    def _spec_names(self, changes: dict) -> tuple[str, list[str]]:
        base = str(self._get("model.base", changes))
        effects = self._get("model.effects", changes) or []
        return base, [str(e) for e in effects if str(e)]  # [""] is none

    def _config(self, changes: dict) -> dict:
        out = {}
        for name in self._model_keys:
            v = self._get(name, changes)
            out[name[len("model."):]] = v
        return out

    def _read(self, changes: dict | None = None) -> ResidualSettings:
        """Settings from the current parameters plus pending ``changes``; raises HystError/ValueError."""
        changes = changes or {}
        base, effects = self._spec_names(changes)
        cfg = self._config(changes)
        model = build_model(base, effects, cfg)
        legacy: dict[str, float] = getattr(model, "legacy_values", dict)()  # added since older files were written
        cfg = {**{k: v for k, v in legacy.items() if f"model.{k}" not in self._model_keys}, **cfg}
        missing = [n for n in model.names if f"model.{n}" not in self._model_keys and n not in legacy]
        if missing:
            raise HystError(f"model {model.name} needs parameters {', '.join(missing)} that were not declared at "
                            "start-up; restart the node with the new params file")
        numeric = set(model.names) | {k[len("model."):] for k in self._numeric_keys}
        words = [n for n in sorted(numeric)
                 if n in cfg and cfg[n] is not None
                 and (isinstance(cfg[n], bool) or not isinstance(cfg[n], (int, float)))]
        if words:  # the model keys are dynamically typed (20 for 20.0): a bool or a word was taken as a number
            raise HystError(f"model.{words[0]} must be a number, not {cfg[words[0]]!r}")
        theta = model.pack({n: float(cfg[n]) for n in model.names})
        if not np.all(np.isfinite(theta)):
            raise HystError("model parameters must be finite")
        for key, ok, what in (("u_scale", lambda v: v > 0, "positive"), ("y_scale", lambda v: v > 0, "positive"),
                              ("dt", lambda v: v >= 0, "0 (not given) or positive")):
            v = cfg.get(key)
            if v is not None and not (math.isfinite(float(v)) and ok(float(v))):  # true was taken as 1
                raise HystError(f"model.{key} must be {what} and finite, not {v!r}")
        # A full-range test input (±10 model units, the fitting convention of hyst_model.models.data_config).
        t = np.arange(1000) * 1e-3
        amp = 10.0 * float(cfg.get("u_scale", 1.0) or 1.0)
        with np.errstate(all="ignore"):
            probe = np.asarray(model.simulate(theta, t, amp * np.sin(2 * np.pi * 2.0 * t)))
        if not np.all(np.isfinite(probe)) or np.max(np.abs(probe)) > 1e3:
            raise HystError("the model diverges on a full-range test sine with these parameters")
        lo, hi = float(np.min(probe)), float(np.max(probe))
        s = ResidualSettings(model, theta, float(self._get("reset_gap", changes)),
                             float(self._get("history", changes)), int(self._get("batch", changes)),
                             u_max=2.0 * amp, y_range=(lo - (hi - lo), hi + (hi - lo)) if hi > lo else
                             (-math.inf, math.inf))
        return s

    def _on_set(self, params) -> SetParametersResult:
        try:
            self._read({p.name: p.value for p in params})
        except (HystError, ValueError, TypeError, KeyError) as err:
            return SetParametersResult(successful=False, reason=str(err))
        return SetParametersResult(successful=True)

    def _after_set(self, params) -> None:
        self._settings = self._read()
        self._reset()
        self.get_logger().info("parameters applied: " + ", ".join(p.name for p in params))

    # Model state ----------------------------------------------------------------------------------------
    def _reset(self) -> None:
        s = self._settings
        self._t_last: float | None = None
        self._y_prev = math.nan  # model units (streaming)
        self._u_prev = math.nan
        if s.streaming:
            p = s.model.to_params(s.theta)
            self._p = p.vector
            self._scale = (p.u_scale, p.y_scale, p.offset)
        self._buf: deque = deque()
        self._pending: list[tuple[object, float, float]] = []

    def _predict_stream(self, u: float) -> float:
        u_scale, y_scale, offset = self._scale
        um = u / u_scale
        if math.isnan(self._y_prev):
            self._y_prev = float(mbw_rest_state(self._p, um))
            self._u_prev = um
        y = float(mbw_step(self._p, self._y_prev, um, self._u_prev))
        self._y_prev, self._u_prev = y, um
        return y_scale * y + offset

    # Messages -------------------------------------------------------------------------------------------
    def _on_state(self, msg: JointState) -> None:
        self._n["states"] += 1
        if not msg.effort or not math.isfinite(msg.effort[0]):
            self._n["bad_states"] += 1
            self.get_logger().warning("state without a finite effort[0] ignored", throttle_duration_sec=1.0)
            return
        if abs(msg.effort[0]) > self._settings.u_max:
            self._n["bad_states"] += 1
            self.get_logger().warning(f"state with effort[0] = {msg.effort[0]:.6g} V ignored: beyond twice the "
                                      f"model's range (±{self._settings.u_max:.6g} V)", throttle_duration_sec=1.0)
            return
        t = _stamp(msg)
        s = self._settings
        if self._t_last is not None and (t - self._t_last > s.reset_gap or t < self._t_last):
            self._n["resets"] += 1
            self.get_logger().info(f"stamp jump of {t - self._t_last:+.3f} s: model restarted at rest")
            self._reset()
        self._t_last = t
        u = float(msg.effort[0])
        y = float(msg.position[0]) if msg.position and math.isfinite(msg.position[0]) else math.nan
        if not (s.y_range[0] <= y <= s.y_range[1]) and math.isfinite(y):
            self._n["bad_readings"] += 1  # the model still runs on the (good) input; this reading is not compared
            self.get_logger().warning(f"reading {y:.6g} m not compared: far outside the model's output range "
                                      f"({s.y_range[0]:.3g}..{s.y_range[1]:.3g} m)", throttle_duration_sec=1.0)
            y = math.nan
        if s.streaming:
            self._publish(msg.header.stamp, self._predict_stream(u), y)
            return
        self._buf.append((t, u))
        while self._buf and t - self._buf[0][0] > s.history:
            self._buf.popleft()
        self._pending.append((msg.header.stamp, t, y))
        if len(self._pending) >= s.batch:
            self._flush()

    def _flush(self) -> None:
        s = self._settings
        tt = np.fromiter((b[0] for b in self._buf), float, len(self._buf))
        uu = np.fromiter((b[1] for b in self._buf), float, len(self._buf))
        t0 = time.perf_counter()
        with np.errstate(all="ignore"):
            yy = np.asarray(s.model.simulate(s.theta, tt, uu), dtype=float)
        spent = time.perf_counter() - t0
        span = self._pending[-1][1] - self._pending[0][1] if len(self._pending) > 1 else 0.0
        if span > 0 and spent > span:
            self.get_logger().warning(
                f"re-simulating {tt.size} samples took {spent * 1e3:.0f} ms for {span * 1e3:.0f} ms of data: the "
                "node falls behind; lower 'history' or raise 'batch'", throttle_duration_sec=5.0)
        k0 = len(tt) - len(self._pending)
        for i, (stamp, _, y) in enumerate(self._pending):
            j = k0 + i
            if j >= 0:
                self._publish(stamp, float(yy[j]), y)
        self._pending.clear()

    def _publish(self, stamp, y_model: float, y_meas: float) -> None:
        if not math.isfinite(y_model):
            return
        m = JointState()
        m.header.stamp = stamp
        m.name = ["stage"]
        m.position = [y_model]
        self._pred_pub.publish(m)
        if math.isfinite(y_meas):
            r = JointState()
            r.header.stamp = stamp
            r.name = ["stage"]
            r.position = [y_meas - y_model]
            self._res_pub.publish(r)
        self._n["published"] += 1

    @property
    def counts(self) -> dict:
        return dict(self._n)

    def _publish_diagnostics(self) -> None:
        """Counts on ``/diagnostics`` every second; WARN while states or readings are being ignored."""
        new_bad = self._n["bad_states"] - self._n_seen["bad_states"]
        new_read = self._n["bad_readings"] - self._n_seen["bad_readings"]
        self._n_seen = dict(self._n)
        said = ([f"{new_bad} state(s) ignored in the last second (non-finite or implausible effort)"] if new_bad
                else []) + ([f"{new_read} reading(s) not compared (far outside the model's output range)"]
                            if new_read else [])
        message = "; ".join(said) or f"model {self._settings.model.name}"
        st = diagnostic_status("hyst_residual", "stage", DiagnosticStatus.WARN if said else DiagnosticStatus.OK,
                               message, self._n)
        self._diag_pub.publish(diagnostic_array(self, [st]))


def main(args=None) -> int:
    """Console script ``hyst_residual_node`` (``--ros-args --params-file P``)."""
    return run_node(ResidualNode, args, prog="hyst_residual_node", usage=USAGE, executor="single")


if __name__ == "__main__":
    raise SystemExit(main())
