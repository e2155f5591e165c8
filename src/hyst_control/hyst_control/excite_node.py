"""hyst_excite_node: play an open-loop voltage excitation for identification (issue 11, Build 3).

Answers every ``/stage/state`` sample with one ``/stage/command`` (``effort[0]`` V, ``header.stamp`` = the stamp of
the state it answers, as the controller does; docs/ARCHITECTURE.md), so it drives the lockstep sim, the realtime
sim and the driver alike. The command answering the state stamped ``t`` is excitation sample
``round((t - t_first)·rate) + 1`` (time-indexed: a missed period skips its sample instead of shifting the rest, and
the jump over a gap is faded in over ``step_rise``; a repeated stamp — lockstep re-announcing sample 0 — is
answered with the same value). After the last sample the
node answers once more with the rest voltage and stops (exit 0). Parameters (all fixed at start): ``profile``,
``rate``, ``v_min``, ``v_max``, ``slew_max``, ``parts``, ``amplitudes``, ``frequency``, ``periods``, ``n_steps``,
``hold``, ``step_rise``, ``f_lo``, ``f_hi``, ``seconds``, ``seed`` (see :mod:`hyst_control.excitation`),
``file`` (play a ``t,u`` CSV in s, V instead — ``hyst excite --out`` writes one; it must be sampled at ``rate``,
stay inside ``v_min``..``v_max`` and ``slew_max`` and start and end at rest, or the node refuses to start, saying
which sample breaks which limit) and ``wait_for_subscribers`` (no answer until ``/stage/command`` has that many
subscribers: 2 with a recorder). A state without a finite position, stamped before the last one answered, or more
than :data:`MAX_JUMP` s ahead of it unconfirmed by the next is not answered but counted (log and ``/diagnostics``,
published every second with the samples answered).
"""
from __future__ import annotations

import math

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from sensor_msgs.msg import JointState

from hyst_common.node import AtomicParametersNode, diagnostic_array, diagnostic_status, fp_range, int_range, run_node
from hyst_common.errors import ConfigError as CommonConfigError
from hyst_common.profiles import CUSTOM_V_MAX, GMA_LIMITS, PEA_LIMITS, custom_range

from .errors import ControlError
from .excitation import (DEFAULT_RATE, MAX_RATE, MIN_RATE, PARTS, Excitation, ExcitationSpec, build_excitation,
                         from_samples)

__all__ = ["ExciteNode", "main", "MAX_JUMP"]

#: A state stamped more than this many seconds after the last one answered is answered only once a second state
#: confirms the jump: the stage paused (a stalled driver) rather than a stray message.
MAX_JUMP = 1.0


class ExciteNode(AtomicParametersNode):
    """Open-loop excitation player; see the module docstring. ``done`` is True after the last sample."""

    def __init__(self, **kwargs) -> None:
        super().__init__("hyst_excite", **kwargs)
        self._declare()
        self.spec = self._read()
        self.source = str(self.get_parameter("file").value).strip()
        self.excitation = _from_file(self.source, self.spec) if self.source else build_excitation(self.spec)
        self.done = False
        self._t_first: float | None = None  # stamp (s) of the first state answered
        self._k_last: int | None = None     # index of the last sample answered
        self._v_last: float | None = None   # the command sent for it (V); set with _k_last
        self._resume = (0.0, 0.0)       # (stamp s, offset V) of the last gap: the offset fades over step_rise
        self.answered = 0
        # states not answered: unreadable (no finite position), stamped before the last one answered, or a jump
        # ahead of more than MAX_JUMP s not yet confirmed by a second state (a stray message stamped in 2033 ended
        # the excitation after 100 of 17 800 samples, without a word)
        self.ignored = {"unreadable": 0, "out_of_order": 0, "jump": 0}
        self._jump_at: int | None = None  # sample index of an unconfirmed jump
        self.add_on_set_parameters_callback(
            lambda _p: SetParametersResult(successful=False, reason="excitation parameters apply at start only"))
        self._pub = self.create_publisher(JointState, "/stage/command", 10000)  # as the controller's: see there
        self.create_subscription(JointState, "/stage/state", self._on_state, 1000)
        self._diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_timer(1.0, self._publish_diagnostics)
        ex = self.excitation
        what = f"file {self.source}" if self.source else ", ".join(self.spec.parts)
        self.get_logger().info(
            f"excitation ready: {what}, {ex.duration:.2f} s at {1 / self.spec.dt:g} Hz, "
            f"{ex.u.min():.3g}..{ex.u.max():.3g} V")

    def _declare(self) -> None:
        d = self.declare_parameter
        ro = dict(read_only=True)
        d("profile", "pea", ParameterDescriptor(
            description="limit defaults: pea (0-150 V) | gma (+-5 V) | custom (another stage: set v_min and v_max)",
            **ro))
        prof = self.get_parameter("profile").value
        if prof not in ("pea", "gma", "custom"):
            raise ControlError(f"profile must be pea, gma or custom, got {prof!r}")
        s = ExcitationSpec()
        d("rate", DEFAULT_RATE, ParameterDescriptor(description="stage sample rate (Hz)",
                                                    floating_point_range=fp_range(MIN_RATE, MAX_RATE), **ro))
        if prof == "custom":  # no default range: the user names the amplifier's
            box = (-CUSTOM_V_MAX, CUSTOM_V_MAX)
            d("v_min", 0.0, ParameterDescriptor(description="lowest command (V) of the stage's amplifier",
                                                floating_point_range=fp_range(*box), **ro))
            d("v_max", 0.0, ParameterDescriptor(description="highest command (V) of the stage's amplifier",
                                                floating_point_range=fp_range(*box), **ro))
            try:
                lim = custom_range(self.get_parameter("v_min").value, self.get_parameter("v_max").value)
            except CommonConfigError as err:
                raise ControlError(str(err)) from err
        else:
            lim = GMA_LIMITS if prof == "gma" else PEA_LIMITS
            d("v_min", lim.v_min, ParameterDescriptor(description="lowest command (V), inside the profile",
                                                      floating_point_range=fp_range(lim.v_min, lim.v_max), **ro))
            d("v_max", lim.v_max, ParameterDescriptor(description="highest command (V), inside the profile",
                                                      floating_point_range=fp_range(lim.v_min, lim.v_max), **ro))
        d("slew_max", float(min(lim.slew_max, 1e9)), ParameterDescriptor(
            description="command slew limit (V/s)", floating_point_range=fp_range(1e-3, 1e9), **ro))
        d("parts", ",".join(s.parts), ParameterDescriptor(description=f"comma list of {', '.join(PARTS)}", **ro))
        d("amplitudes", list(s.amplitudes), ParameterDescriptor(
            description="fractions of the range for sines/triangles (largest: multisine, sweep)", **ro))
        for name, lo, hi, txt in (("frequency", 1e-3, 2500.0, "sine/triangle frequency (Hz)"),
                                  ("hold", 0.0, 60.0, "step hold and pause between parts (s)"),
                                  ("step_rise", 0.0, 10.0, "raised-cosine rise time of each step (s)"),
                                  ("f_lo", 1e-3, 2500.0, "multisine/sweep lowest frequency (Hz)"),
                                  ("f_hi", 1e-3, 2500.0, "multisine/sweep highest frequency (Hz)"),
                                  ("seconds", 1e-3, 3600.0, "multisine and sweep length (s)")):
            d(name, float(getattr(s, name)), ParameterDescriptor(description=txt, floating_point_range=fp_range(lo, hi),
                                                                 **ro))
        d("periods", s.periods, ParameterDescriptor(description="periods per sine/triangle amplitude",
                                                    integer_range=int_range(1, 10_000), **ro))
        d("n_steps", s.n_steps, ParameterDescriptor(description="random step levels",
                                                    integer_range=int_range(1, 10_000), **ro))
        d("wait_for_subscribers", 1, ParameterDescriptor(
            description="answer no state until /stage/command has this many subscribers (stage + recorder = 2), "
                        "so a recorder never misses the first commands", integer_range=int_range(1, 100), **ro))
        d("seed", 0, ParameterDescriptor(description="seed of step levels, multisine phases and noise",
                                         integer_range=int_range(0, 2**31 - 1), **ro))
        d("file", "", ParameterDescriptor(
            description="play this t,u CSV (s, V; e.g. from hyst excite --out) instead of generating parts; it must "
                        "be sampled at rate and keep the range and slew limits", **ro))

    def _read(self) -> ExcitationSpec:
        def g(name):
            return self.get_parameter(name).value

        parts = tuple(p.strip() for p in str(g("parts")).split(",") if p.strip())
        return ExcitationSpec(
            v_min=float(g("v_min")), v_max=float(g("v_max")), slew_max=float(g("slew_max")), dt=1.0 / float(g("rate")),
            parts=parts, amplitudes=tuple(float(a) for a in g("amplitudes")), frequency=float(g("frequency")),
            periods=int(g("periods")), n_steps=int(g("n_steps")), hold=float(g("hold")),
            step_rise=float(g("step_rise")), f_lo=float(g("f_lo")),
            f_hi=float(g("f_hi")), seconds=float(g("seconds")), seed=int(g("seed")))

    def _on_state(self, msg: JointState) -> None:
        if self.done:
            return
        t = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
        if self._t_first is None:
            if self._pub.get_subscription_count() < self.get_parameter("wait_for_subscribers").value:
                return  # the lockstep sim re-announces sample 0; a realtime stage just starts later
            self._t_first = t
        k = int(round((t - self._t_first) / self.spec.dt)) + 1
        if not self._plausible(msg, t, k):
            return
        u = self.excitation.u
        if k >= len(u):
            v, self.done = self.spec.rest, True
            self.get_logger().info(f"excitation finished after {self.answered} samples"
                                   + (f"; {sum(self.ignored.values())} state(s) not answered: {self.ignored}"
                                      if any(self.ignored.values()) else ""))
        else:
            v = self._blended(t, k)
        out = JointState()
        out.header.stamp = msg.header.stamp
        out.name = ["stage"]
        out.effort = [v if math.isfinite(v) else self.spec.rest]
        self._pub.publish(out)
        self._k_last, self._v_last = k, out.effort[0]
        self.answered += 1

    def _plausible(self, msg: JointState, t: float, k: int) -> bool:
        """Whether to answer this state: a finite position, not before the last state answered, and a jump ahead
        of more than :data:`MAX_JUMP` s only when a second state confirms it (a stage that really paused; the
        lockstep sim re-announces its state until answered). Every state refused is counted and logged."""
        why = None
        if not (len(msg.position) and all(math.isfinite(p) for p in msg.position) and math.isfinite(t)):
            why = "unreadable"
        elif self._k_last is not None and k < self._k_last:
            why = "out_of_order"
        elif self._k_last is not None and (k - self._k_last) * self.spec.dt > MAX_JUMP:
            confirmed = self._jump_at is not None and abs(k - self._jump_at) <= 2
            self._jump_at = None if confirmed else k
            why = None if confirmed else "jump"
        if why is None:
            return True
        self.ignored[why] += 1
        self.get_logger().warning(f"state stamped {t:.6g} s not answered ({why.replace('_', ' ')}; after sample "
                                  f"{self._k_last}); {sum(self.ignored.values())} ignored so far",
                                  throttle_duration_sec=1.0)
        return False

    def _publish_diagnostics(self) -> None:
        n = sum(self.ignored.values())
        message = (f"{n} state(s) not answered" if n else "playing") if not self.done else "finished"
        vals = {"answered": self.answered, "samples": int(self.excitation.u.size), "done": self.done,
                **{f"ignored_{k}": v for k, v in self.ignored.items()}}
        st = diagnostic_status("hyst_excite", "stage", DiagnosticStatus.WARN if n else DiagnosticStatus.OK,
                               message, vals)
        self._diag_pub.publish(diagnostic_array(self, [st]))

    def flush(self, timeout: float) -> bool:
        """Wait until every subscriber has acknowledged every command (reliable QoS), at most ``timeout`` s.

        Leaving at once lost up to 600 commands in a bag: a loaded recorder had not received them when the
        publisher was destroyed, though the stage had.
        """
        from rclpy.duration import Duration
        return self._pub.wait_for_all_acked(Duration(seconds=timeout))

    def _blended(self, t: float, k: int) -> float:
        """Excitation sample ``k``, resumed smoothly after missed periods.

        Over a gap the stage held the last voltage while the excitation moved on; jumping to sample ``k`` (up to
        the full range in one period) drove the simulated MBW stage onto its end stop. The difference fades out
        by a raised cosine over ``step_rise``, as the steps rise; the timing of the rest is unchanged.
        """
        u = self.excitation.u
        uk = float(u[max(k, 0)])
        if self._k_last is not None and self._v_last is not None and k > self._k_last + 1 and math.isfinite(uk) \
                and self.spec.step_rise > 0:
            self._resume = (t, self._v_last - uk)
        t0, off = self._resume
        x = (t - t0) / self.spec.step_rise if self.spec.step_rise > 0 else 1.0
        return uk + off * 0.5 * (1.0 + math.cos(math.pi * x)) if 0.0 <= x < 1.0 else uk


def _from_file(path: str, spec: ExcitationSpec) -> Excitation:
    """The excitation of a ``t,u`` CSV, checked against the node's limits (one error with the reason)."""
    from hyst_model.errors import HystError
    from hyst_model.io.csvio import read_input_csv
    try:
        t, u = read_input_csv(path)
    except (HystError, OSError) as err:
        raise ControlError(f"file {path}: {err}") from err
    try:
        return from_samples(t, u, spec)
    except ControlError as err:
        raise ControlError(f"file {path}: {err}") from err


def _flush(node: "ExciteNode", stopped: bool) -> None:
    if node.done and not node.flush(30.0):  # every command must reach every subscriber (a lagging recorder)
        node.get_logger().warning("not every subscriber acknowledged the last commands within 30 s")


def main(args=None) -> int:
    """Console script ``hyst_excite_node`` (``--ros-args -p rate:=2000.0 -p parts:=steps,sweep``)."""
    return run_node(ExciteNode, args, prog="hyst_excite_node", errors=(ControlError,), executor="single",
                    until=lambda n: n.done, on_exit=_flush,
                    usage="usage: hyst_excite_node [--ros-args -p NAME:=VALUE ...]\n\n" + __doc__)


if __name__ == "__main__":
    raise SystemExit(main())
