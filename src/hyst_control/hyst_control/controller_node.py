"""hyst_controller_node: DPPC / DMRAC / PID / open loop on ROS topics, switchable while running.

Subscribes ``/stage/state`` (``position[0]`` m, ``effort[0]`` applied V) and ``/stage/reference``
(``position[0]`` m, ``velocity[0]`` m/s); publishes ``/stage/command`` (``effort[0]`` V, ``header.stamp`` = the
stamp of the state sample it answers), ``/controller/state`` (named scalars: error, epsilon, lambda, nu, estimates
..., with a drift effect ``drift`` and for ``drift.side: sensor`` ``position_error``, in ``position``) and
``/diagnostics``.

The command answering the state stamped t_k acts at the next sample, so the reference is evaluated at
t_k + 1/rate: the newest reference sample is extrapolated with its rate from its own stamp (at most 50 ms; both
stamps come from the same clock in realtime operation; at most 5 ms ahead). Parameters: ``algorithm`` (bumpless switch
at run time), per-algorithm gains ``dppc.*``, ``dmrac.*``, ``pid.*`` (ranges declared, consistency checked in the on-set
callback), limits ``v_min``/``v_max``/``slew_max``/``v_safe``, ``watchdog_periods`` and the stage model
``model.*`` (from ``--ros-args --params-file P``; the identification node may push new values at run time).
Watchdog: no state for ``watchdog_periods``/``rate`` seconds → command ``v_safe`` (slew-limited), log, and
ERROR on /diagnostics; the next state restarts the controller bumplessly.

Length (~460 lines): one node class is the adapter between messages/parameters and the pure controllers; the
settings and their checks (:func:`~hyst_control.controller_settings.read_settings`), gains, stability check and
compensation it calls live in their own modules, and what remains (declare, swap, the per-sample callback,
switching, diagnostics) shares the node's state.
"""
from __future__ import annotations

import math
import time
from typing import Any, Callable

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.exceptions import ParameterUninitializedException
from sensor_msgs.msg import JointState

from hyst_common.node import AtomicParametersNode, diagnostic_array, diagnostic_status, fp_range, int_range, run_node
from hyst_common.errors import ConfigError
from hyst_common.profiles import CUSTOM_V_MAX, custom_base, custom_range, get_profile
from hyst_common.runtime import RT_PRIORITY_MAX, set_realtime

from hyst_model.core import MBWParams

from .base import hand_over
from .compensation import effect_parameters
from .errors import ControlError
from .pid import PIDGains, gains_for
from .controllers import ALGORITHMS, make_controller, make_supervised
from .supervisor import Supervised
from .controller_settings import GAINS, MODEL_KEYS, ControllerSettings, model_divergence, profile_model, read_settings
from .stability import StabilityVerdict

__all__ = ["ControllerNode", "ControllerSettings", "main"]

_F = float


class ControllerNode(AtomicParametersNode):
    """The controller node; see the module docstring."""

    def __init__(self, **kwargs) -> None:
        super().__init__("hyst_controller", **kwargs)
        self._declare()
        self._settings = self._read()  # start-up values were validated by _read
        self._compensating: list[str] = []
        self._unused = self._unused_model_terms()
        if self._unused:
            self.get_logger().warning(self._unused)
        if self._compensating:
            self.get_logger().info("compensating the model's " + ", ".join(self._compensating))
        self._log_stability(None, self._settings.stability)
        if self._settings.divergence:
            self.get_logger().warning(self._settings.divergence)
        self.scheduling = set_realtime(int(self.get_parameter("rt_priority").value))
        if self.get_parameter("rt_priority").value and self.scheduling.policy != "fifo":
            self.get_logger().warning(f"{self.scheduling.note}; running with normal scheduling")
        self._ctrl: Any = None  # the running law (possibly Compensated); None until the first state
        self._y = math.nan
        self._ref: tuple[float, float, float] | None = None  # (t_stamp, r, rdot)
        self._source: Callable[[float], float] | None = None  # in-process reference r(t) (:meth:`follow`)
        self._last_state_wall: float | None = None
        self._tripped = False
        self._ramp_wall = 0.0  # monotonic time of the watchdog ramp's last step
        self._n = dict.fromkeys(("states", "commands", "bad_states", "bad_refs", "unreachable_refs",
                                 "watchdog_trips", "switches", "gaps", "oscillations"), 0)
        self._n_seen = dict(self._n)  # the counts at the last /diagnostics: what is new since
        self._n_osc = 0           # oscillation-watch events of the running law already reported
        self._oscillation = ""    # the newest of them, kept on /diagnostics
        self._t_last: float | None = None  # stamp of the previous state
        self._t0: float | None = None  # first state stamp (internal reference time origin)
        self._pending = math.nan  # reference targeted by the last command: compared with the next sample
        self._skip = 0            # samples after a (re)start or switch left out of the tracking statistics
        self._stats: dict[str, list] = {}  # algorithm -> [n, sum e², max |e|]
        self.add_on_set_parameters_callback(self._on_set)
        self.add_post_set_parameters_callback(self._after_set)
        # deep history: a recorder slow for a moment (lockstep runs at the pace of the slowest reliable reader of
        # /stage/state, which can be ~1000 samples behind) must not lose commands; never blocks the loop
        self._cmd_pub = self.create_publisher(JointState, "/stage/command", 10000)
        self._warned_commanders = False
        self._state_pub = self.create_publisher(JointState, "/controller/state", 1000)
        self._diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_subscription(JointState, "/stage/state", self._on_state, 10)
        self.create_subscription(JointState, "/stage/reference", self._on_reference, 10)
        self.create_timer(0.02, self._watchdog)
        self.create_timer(1.0, self._diagnostics)
        self.get_logger().info(f"controller ready: {self._settings.algorithm} at {self._settings.rate:g} Hz, "
                               f"scheduling {self.scheduling}")

    # Parameters -----------------------------------------------------------------------------------------
    def _declare(self) -> None:
        d = self.declare_parameter
        d("profile", "pea", ParameterDescriptor(
            description="limit defaults: pea (0-150 V) | gma (+-5 V) | custom (another stage: needs v_min, v_max "
                        "and its model, --params-file P from hyst fit --out)", read_only=True,
            additional_constraints="one of: pea, gma, custom"))
        name = str(self.get_parameter("profile").value).strip().lower()
        custom = name == "custom"
        lim = None if custom else get_profile(name).limits()  # ConfigError (exit 2) for an unknown name
        box = fp_range(-CUSTOM_V_MAX, CUSTOM_V_MAX) if custom else fp_range(-200, 200)
        d("algorithm", "dppc", ParameterDescriptor(description=" | ".join(ALGORITHMS) + " (bumpless switch)"))
        d("rate", 1000.0, ParameterDescriptor(description="expected state rate (Hz)",
                                              floating_point_range=fp_range(1, 5000)))
        for n, v, txt in (("v_min", lim.v_min if lim else 0.0, "lowest command (V)"),
                          ("v_max", lim.v_max if lim else 0.0, "highest command (V)")):
            d(n, v, ParameterDescriptor(description=txt, floating_point_range=box))
        if lim is None:  # another stage: no default range, the user names the amplifier's
            try:
                lim = custom_range(self.get_parameter("v_min").value, self.get_parameter("v_max").value)
            except ConfigError as err:
                raise ControlError(str(err)) from err
            if not any(k.startswith("model.") for k in self._parameter_overrides):
                raise ControlError("profile custom needs the stage's model: --params-file P (hyst fit --out); the "
                                   "embedded models are the PEA's and the GMA's")
        d("v_safe", lim.v_safe, ParameterDescriptor(description="command held by the watchdog (V)",
                                                    floating_point_range=box))
        d("slew_max", lim.slew_max, ParameterDescriptor(description="command slew limit (V/s)",
                                                        floating_point_range=fp_range(1e-3, 1e9)))
        d("safe_ramp_rate", 100.0, ParameterDescriptor(
            description="rate of the watchdog's ramp to v_safe (V/s; as the driver's and the sim's own timeouts)",
            floating_point_range=fp_range(1e-3, 1e9)))
        d("watchdog_periods", 100, ParameterDescriptor(
            description="no state for this many periods -> v_safe", integer_range=int_range(2, 1_000_000)))
        d("reference", "", ParameterDescriptor(
            description="'' = follow /stage/reference; a spec (sine:5, step, c1, ...) = generate it internally "
                        "at the state stamps (deterministic, e.g. with a lockstep sim); time 0 = first state"))
        d("rt_priority", 0, ParameterDescriptor(
            description="SCHED_FIFO priority of the node's threads (0 = normal scheduling; applies at start; "
                        "see hyst_common.runtime)", read_only=True,
            integer_range=int_range(0, RT_PRIORITY_MAX)))
        d("state_decimation", 10, ParameterDescriptor(
            description="publish /controller/state every N samples", integer_range=int_range(1, 100_000)))
        d("dmrac.initial", "model", ParameterDescriptor(description="initial estimates: model | cs0..cs3 (Table 5.3)"))
        d("stability.policy", "derate", ParameterDescriptor(
            description="gains unstable against model.dynamics (the stage resonance): derate (run the least-derated "
                        "robust gains, WARN) | warn (run them anyway, WARN) | refuse (reject, exit 2 at start)"))
        d("stability.notch", True, ParameterDescriptor(
            description="pid under policy derate, configured without a notch: also try a notch on the command at "
                        "the identified resonance and run it when it keeps more gain (hyst_control.notch)"))
        d("stability.gain_margin", 2.0, ParameterDescriptor(
            description="gain margin (factor, both ways) the loop with the resonance must keep",
            floating_point_range=fp_range(1.0, 10.0)))
        m = profile_model(custom_base(lim.v_min, lim.v_max) if custom else name)  # custom: the file's replace it
        d("model.base", "mbw", ParameterDescriptor(description="base model of the params file (controllers need mbw)"))
        d("model.effects", [""], ParameterDescriptor(
            description="effects of the params file (innermost first): those with an inverse are compensated "
                        "(creep, asymmetry, saturation, delay); the others are reported at start, on every "
                        "change and on /diagnostics, never silently dropped"))
        d("model.dt", 0.0, ParameterDescriptor(
            description="sample period the model was identified at (s); 0 = unknown; must equal 1/rate",
            floating_point_range=fp_range(0.0, 1.0)))
        for key in MODEL_KEYS:
            d(f"model.{key}", _F(getattr(m, key)), ParameterDescriptor(
                description=f"stage model {key} (params file; thesis ν convention)",
                floating_point_range=fp_range(-1e6, 1e6)))
        d("model.offset_bound", 1e-3, ParameterDescriptor(
            description="bound of the fitted offset (m; params file provenance, not used by the laws)",
            floating_point_range=fp_range(0.0, 1e6)))
        # Every built-in effect's parameters at their identity values: a params file or a push may carry any.
        self._effect_keys = effect_parameters(1.0 / self.get_parameter("rate").value, m.u_scale, m.y_scale)
        for key, (default, txt) in self._effect_keys.items():
            if key in ("dynamics.fn", "dynamics.zeta", "dynamics.part", "dynamics.fn2", "dynamics.zeta2"):  # checked
                txt += "; with dynamics in model.effects the gains are checked against it (hyst_control.stability)"
            desc = ParameterDescriptor(description=txt, floating_point_range=fp_range(-1e6, 1e6)) \
                if isinstance(default, float) else ParameterDescriptor(description=txt)
            d(f"model.{key}", default, desc)
        pid = self._pid_defaults()
        for alg, (_, spec) in GAINS.items():  # from the gains dataclasses' field metadata (hyst_common.params)
            for name, g in spec.items():
                desc = ParameterDescriptor(description=g.description) if g.lo is None or g.hi is None else \
                    ParameterDescriptor(description=g.description, floating_point_range=fp_range(g.lo, g.hi))
                d(f"{alg}.{name}", getattr(pid, name) if alg == "pid" else g.default, desc)

    def _pid_defaults(self) -> PIDGains:
        """The PID's default gains moved to the start-up model's gain (:func:`~hyst_control.pid.gains_for`): the
        SI defaults are the PEA's, and the GMA's 4 µm/V stage rang at them (1.8 µm on a 10 Hz sine after three
        deratings, against 0.13 µm scaled). Declared as the defaults, so what runs is what the parameters show; a
        later model push does not rescale gains the user may have set."""
        g = self.get_parameter
        try:
            m = MBWParams(**{k: float(g(f"model.{k}").value) for k in MODEL_KEYS})
            return gains_for(m, float(g("v_min").value), float(g("v_max").value))
        except (ValueError, TypeError, ArithmeticError):  # a bad model is refused later, with its reason
            return PIDGains()

    def _read(self, changes: dict | None = None) -> ControllerSettings:
        """Settings from current parameters (+ pending ``changes``); raises ControlError/ValueError with a reason."""
        def get(name):
            if changes and name in changes:
                return changes[name]
            try:
                return self.get_parameter(name).value
            except ParameterUninitializedException:
                if name == "model.effects":  # declared as a list without a value: none
                    return ()
                raise

        return read_settings(get, tuple(self._effect_keys))

    def _on_set(self, params) -> SetParametersResult:
        try:
            self._read({p.name: p.value for p in params})
        except (ControlError, ValueError, TypeError) as err:
            return SetParametersResult(successful=False, reason=str(err))
        return SetParametersResult(successful=True)

    def _after_set(self, params) -> None:
        old, new = self._settings, self._read()
        self._settings = new
        self._log_stability(old.stability, new.stability)
        if new.divergence and new.divergence != old.divergence:
            self.get_logger().warning(new.divergence)
        if new.effects != old.effects or new.effect_values != old.effect_values:
            unused = self._unused_model_terms()
            if unused and unused != self._unused:
                self.get_logger().warning(unused)
            self._unused = unused
        c = self._ctrl
        if c is None:
            return
        if new.reference != old.reference:
            self._t0 = None
        # Effect states (creep lags, the Smith predictor's model) belong to one model: a new model with effects
        # starts a fresh compensated controller, handed over bumplessly.
        compensated = bool(new.effects or old.effects) and (
            new.model != old.model or new.effects != old.effects or new.effect_values != old.effect_values)
        if new.algorithm != old.algorithm or new.rate != old.rate or new.dmrac_initial != old.dmrac_initial \
                or compensated:
            self._switch(new)
            return
        c.limits = new.limits
        if new.model != old.model and hasattr(c, "set_model"):
            c.set_model(new.model)
        if new.gains(new.algorithm) != old.gains(new.algorithm) and hasattr(c, "set_gains"):
            c.set_gains(new.gains(new.algorithm))
        self.get_logger().info("parameters applied: " + ", ".join(p.name for p in params))

    def _build(self, s: ControllerSettings) -> Supervised:
        """The law of ``s``, watched for oscillation (:mod:`hyst_control.supervisor`): rebuilt derated if it
        rings on a mode the model does not know (only reported under ``stability.policy: warn``). Every caller
        adopts it, so the old law's oscillation record is cleared here once it is built."""
        def make(alg: str, gains):  # at rebuild time: the settings then in force (a model push since, ...)
            cur = self._settings
            if alg != cur.algorithm:  # the open-loop fallback: refused (ControlError) for a runaway model
                model_divergence(alg, cur.model, cur.compensation(), cur.limits, 1.0 / cur.rate)
            return make_controller(alg, cur.model, 1.0 / cur.rate, cur.limits, gains, cur.dmrac_initial,
                                   cur.compensation())

        act = str(self.get_parameter("stability.policy").value) != "warn"
        law = make_supervised(s.algorithm, s.model, 1.0 / s.rate, s.limits, s.gains(s.algorithm), s.dmrac_initial,
                              s.compensation(), act, rebuild=make)
        self._n_osc, self._oscillation = 0, ""  # a fresh law: the old one's derating no longer stands
        return law

    def _report_oscillation(self) -> None:
        """Log and keep for /diagnostics what the oscillation watch did since the last sample."""
        events = getattr(self._ctrl, "events", ())
        for msg in events[self._n_osc:]:
            self.get_logger().warning(msg)
            self._oscillation = msg
            self._n["oscillations"] += 1
        self._n_osc = len(events)

    def _switch(self, s: ControllerSettings) -> None:
        new = self._build(s)
        self._ctrl = hand_over(new, self._ctrl, self._y) if math.isfinite(self._y) else None
        self._n["switches"] += 1
        self._skip = int(0.25 * s.rate)
        self.get_logger().info(f"switched to {s.algorithm} (bumpless)")

    def _log_stability(self, old: StabilityVerdict | None, new: StabilityVerdict | None) -> None:
        """One log line when the verdict of the resonance check changes (start, model push, gains, switch)."""
        if new is None or not new.message or (old is not None and old.message == new.message):
            return
        if new.warn:  # two call sites: rclpy's logger refuses a second severity at one site
            self.get_logger().warning(new.message)
        else:
            self.get_logger().info(new.message)

    # Messages -------------------------------------------------------------------------------------------
    def follow(self, source: Callable[[float], float] | None) -> None:
        """Take the reference from ``source`` (r in m at a time in s on the state stamps' clock) instead of
        ``/stage/reference``; None returns to the topic. For a reference generator in the same process
        (``hyst_loop_node``): exact at each sample, no extrapolation, no message per sample. The ``reference``
        parameter (an internal generator) still takes precedence."""
        self._source = source

    def _on_reference(self, msg: JointState) -> None:
        if not msg.position or not math.isfinite(msg.position[0]):
            self._n["bad_refs"] += 1
            self.get_logger().warning("reference without a finite position[0] ignored (the last one is held)",
                                      throttle_duration_sec=1.0)
            return
        why = self._settings.plausible_reference(float(msg.position[0]))
        if why:  # held as a NaN is, and counted: it must not drive the command to the range's end
            self._n["bad_refs"] += 1
            self.get_logger().warning(f"reference ignored, taken for a corrupt sample: {why}",
                                      throttle_duration_sec=1.0)
            return
        v = float(msg.velocity[0]) if msg.velocity else 0.0
        why = self._settings.plausible_velocity(v)
        if why:  # the position is good: keep it, without the velocity (no extrapolation), and count it
            self._n["bad_refs"] += 1
            self.get_logger().warning(f"reference velocity ignored, taken for a corrupt sample: {why}",
                                      throttle_duration_sec=1.0)
            v = 0.0
        t = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
        self._ref = (t, _F(msg.position[0]), _F(v))

    def _target(self, t_state: float, y: float, ahead: float = 0.0) -> float:
        """Reference for the next sample, ``ahead`` seconds further (a compensated delay's preview)."""
        gen = self._settings.reference
        if gen is not None:
            if self._t0 is None:
                self._t0 = t_state
            return gen(t_state + 1.0 / self._settings.rate + ahead - self._t0)
        if self._source is not None:
            return _F(self._source(t_state + 1.0 / self._settings.rate + ahead))
        if self._ref is None:
            return self._ctrl.last_reference if self._ctrl is not None else y  # hold where the stage is
        t_ref, r, v = self._ref
        # Linear extrapolation is only good for a few ms (a 5 Hz, 10 µm sine bends by 12 µm in 50 ms): a stale
        # reference is extrapolated by at most 5 ms beyond the preview.
        lead = min(max(t_state + 1.0 / self._settings.rate - t_ref, 0.0), 0.005) + ahead
        return r + v * lead

    def _on_state(self, msg: JointState) -> None:
        self._last_state_wall = time.monotonic()
        self._n["states"] += 1
        if not msg.position or not math.isfinite(msg.position[0]):
            self._n["bad_states"] += 1
            self.get_logger().warning("state without a finite position[0] ignored", throttle_duration_sec=1.0)
            if self._ctrl is not None:
                self._publish_command(msg.header.stamp, self._ctrl.last_command)  # answer: hold
            return
        s = self._settings
        u_read = float(msg.effort[0]) if msg.effort else None
        why = s.plausible(float(msg.position[0]), u_read)
        if why:  # one corrupt sample must not move the stage: held as a NaN is
            self._n["bad_states"] += 1
            self.get_logger().warning(f"state ignored, taken for a corrupt sample: {why}",
                                      throttle_duration_sec=1.0)
            if self._ctrl is not None:
                self._publish_command(msg.header.stamp, self._ctrl.last_command)
            return
        y = _F(msg.position[0])
        self._y = y
        t = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
        if self._ctrl is None or self._tripped:
            u0 = _F(msg.effort[0]) if msg.effort and math.isfinite(msg.effort[0]) else s.limits.v_safe
            c = self._build(s)
            no_reference = self._ref is None and self._source is None and s.reference is None
            c.reset(y, u0, y if no_reference else self._target(t, y))
            self._ctrl = c
            self._skip = int(0.25 * s.rate)
            self._pending = math.nan
            if self._tripped:
                self.get_logger().info("states are back: controller restarted bumplessly")
            self._tripped = False
        else:
            if msg.effort and math.isfinite(msg.effort[0]):
                self._ctrl.sync_applied(_F(msg.effort[0]))
            if self._t_last is not None and t - self._t_last > 1.5 / s.rate:
                self._ctrl.notice_gap()
                self._n["gaps"] += 1
        self._t_last = t
        if self._skip > 0:
            self._skip -= 1
        elif math.isfinite(self._pending):
            e = y - self._pending
            st = self._stats.setdefault(s.algorithm, [0, 0.0, 0.0])
            st[0] += 1
            st[1] += e * e
            st[2] = max(st[2], abs(e))
        r = self._target(t, y)
        self._pending = r
        if s.stroke is not None and not s.reachable(r):
            self._n["unreachable_refs"] += 1
            self.get_logger().warning(f"reference {r:.6g} m is beyond the stage's travel {s.stroke[0]:.3g}..."
                                      f"{s.stroke[1]:.3g} m (its rest displacement at v_min..v_max): the command "
                                      "stays at its limit", throttle_duration_sec=5.0)
        ahead = float(getattr(self._ctrl, "preview", 0.0))
        u = self._ctrl.step(self._target(t, y, ahead) if ahead > 0 else r, y)
        self._publish_command(msg.header.stamp, u)
        if len(getattr(self._ctrl, "events", ())) != self._n_osc:
            self._report_oscillation()
        if self._n["commands"] % s.state_decimation == 0:
            st = self._ctrl.state()
            out = JointState()
            out.header.stamp = msg.header.stamp
            out.name = list(st)
            out.position = [_F(v) for v in st.values()]
            self._state_pub.publish(out)

    def _publish_command(self, stamp, u: float) -> None:
        out = JointState()
        out.header.stamp = stamp
        out.name = ["stage"]
        out.effort = [_F(u)]
        self._cmd_pub.publish(out)
        self._n["commands"] += 1

    # Watchdog and diagnostics ---------------------------------------------------------------------------
    def _watchdog(self) -> None:
        s = self._settings
        if self._last_state_wall is None or self._ctrl is None:
            return
        silent = time.monotonic() - self._last_state_wall
        if silent < s.watchdog_periods / s.rate:
            return
        if not self._tripped:
            self._tripped = True
            self._n["watchdog_trips"] += 1
            self.get_logger().error(f"no /stage/state for {silent:.3f} s: ramping to v_safe = {s.limits.v_safe} V "
                                    f"at {s.safe_ramp_rate:g} V/s")
            self._ramp_wall = time.monotonic()
        now = time.monotonic()
        prev = self._ctrl.last_command
        step = s.safe_ramp_rate * min(now - self._ramp_wall, 0.1)  # a late timer tick is no licence to jump
        self._ramp_wall = now
        target = s.limits.v_safe if not math.isfinite(prev) else \
            prev + max(-step, min(step, s.limits.v_safe - prev))
        u = s.limits.apply(target, prev, 0.02)
        getattr(self._ctrl, "inner", self._ctrl)._u_prev = u  # the watchdog owns the output while tripped
        self._publish_command(self.get_clock().now().to_msg(), u)

    def _diagnostics(self) -> None:
        if self._tripped:
            level, message = DiagnosticStatus.ERROR, "watchdog: no /stage/state, holding v_safe"
        elif self._ctrl is None:
            level, message = DiagnosticStatus.WARN, "waiting for /stage/state"
        else:
            level, message = DiagnosticStatus.OK, f"{self._settings.algorithm} running"
        new = {k: self._n[k] - self._n_seen.get(k, 0) for k in ("bad_states", "bad_refs", "unreachable_refs")}
        self._n_seen = dict(self._n)
        said = {"bad_states": "corrupt or non-finite states ignored",
                "bad_refs": "non-finite or implausible references ignored",
                "unreachable_refs": "references beyond the stage's travel"}
        if any(new.values()):  # what went wrong since the last report, while it goes on
            level = max(level, DiagnosticStatus.WARN)
            message += "; " + ", ".join(f"{n} {said[k]}" for k, n in new.items() if n)
        if self._unused:  # whatever else is going on, the dropped model terms stay visible
            level = max(level, DiagnosticStatus.WARN)
            message += f"; {self._unused}"
        if self._oscillation:  # the oscillation watch derated the law (or, under policy warn, only saw it)
            level = max(level, DiagnosticStatus.WARN)
            message += f"; {self._oscillation}"
        if self._settings.divergence:  # the feedback laws run it; the open-loop parts would not
            level = max(level, DiagnosticStatus.WARN)
            message += f"; {self._settings.divergence}"
        stab = self._settings.stability
        if stab is not None and stab.warn:  # derated (or running unstable gains under policy warn)
            level = max(level, DiagnosticStatus.WARN)
            message += f"; {stab.message}"
        others = self._other_commanders()
        if others:  # two sources of /stage/command: the stage follows whichever wrote last
            level = max(level, DiagnosticStatus.WARN)
            message += (f"; {others} other publisher(s) on {self._cmd_pub.topic_name}: another controller or "
                        "excitation is commanding this stage too")
        vals = dict(self._n, algorithm=self._settings.algorithm, other_command_publishers=others,
                    compensated=",".join(self._compensating))
        if self._unused:
            vals["unused_model_terms"] = self._unused
        if stab is not None and stab.running is not None:
            vals.update(stability=stab.message, spectral_radius=f"{stab.running.spectral_radius:.4f}",
                        gain_margin=f"{stab.running.gain_margin_up:.3g}",
                        derated=", ".join(f"{n}={b:.6g}" for n, _, b in stab.derated))
        if self._ctrl is not None:
            vals.update(saturated=int(self._ctrl.state().get("saturated", 0)))
        for a, m in self.tracking_summary().items():
            vals[f"rmse_{a}"] = f"{m['rmse']:.3e}"
            vals[f"mae_{a}"] = f"{m['mae']:.3e}"
        st = diagnostic_status("hyst_controller", "stage", level, message, vals)
        self._diag_pub.publish(diagnostic_array(self, [st]))

    def _other_commanders(self) -> int:
        """Publishers on the command topic besides this node (from the ROS graph); logged once when they appear."""
        n = max(self.count_publishers(self._cmd_pub.topic_name) - 1, 0)
        if n and not self._warned_commanders:
            self.get_logger().warning(f"{n} other publisher(s) on {self._cmd_pub.topic_name}: another controller "
                                      "or excitation node is commanding this stage too")
        self._warned_commanders = bool(n)
        return n

    def _unused_model_terms(self) -> str:
        """What the params file (or a push) says about the stage that the control laws do not use, in words.

        Effects with an inverse are compensated (:mod:`hyst_control.compensation`); the rest (drift, a resonance,
        a user effect unknown here) and ``model.*`` keys this node does not know must be visible: '' when
        nothing is dropped.
        """
        comp = self._settings.compensation()
        self._compensating = comp.names
        extra = sorted(k for k in self._parameter_overrides
                       if k.startswith("model.") and not self.has_parameter(k))
        parts = []
        if comp.unused:
            parts.append("the control laws do not compensate "
                         + "; ".join(f"{k} ({v})" for k, v in comp.unused.items()))
        if comp.sensor_only:
            parts.append(f"open_loop does not compensate {', '.join(comp.sensor_only)} (estimated from the sensor, "
                         "which the open-loop inverse does not read)")
        if extra:
            parts.append(f"model parameters unknown to this node are not used ({', '.join(extra[:6])}"
                         f"{', ...' if len(extra) > 6 else ''})")
        return "; ".join(parts)

    @property
    def counts(self) -> dict:
        return dict(self._n)

    def tracking_summary(self) -> dict:
        """Per algorithm: samples, RMSE and MAE (m) of y_k against the reference targeted for sample k,
        excluding 0.25 s after each start or switch."""
        return {a: {"samples": n, "rmse": math.sqrt(s2 / n) if n else math.nan, "mae": mx}
                for a, (n, s2, mx) in self._stats.items()}


def main(args=None) -> int:
    """Console script ``hyst_controller_node`` (``--ros-args -p algorithm:=dmrac --params-file P``)."""
    return run_node(ControllerNode, args, prog="hyst_controller_node", errors=(ControlError,),
                    usage="usage: hyst_controller_node [--ros-args -p NAME:=VALUE ... --params-file P]\n\n" + __doc__)


if __name__ == "__main__":
    raise SystemExit(main())
