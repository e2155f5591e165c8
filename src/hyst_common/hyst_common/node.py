"""The one way to run a hyst node, and parameter sets that are all or nothing.

With the ``*_node.py`` modules this is the only place that imports rclpy (docs/ARCHITECTURE.md).

:func:`run_node` is every node's ``main``: ``--help`` answered before ROS starts, unexpected arguments refused
with one line, SIGINT/SIGTERM turned into a flag the spin loop reads (rclpy's own handlers are off: a
``KeyboardInterrupt`` raised inside a subscription callback came back from the EventsExecutor as a bare
``RuntimeError`` — exit 1 with a traceback in ≈ 5 of 100 stops), a start-up error (a parameter out of its range,
a rejected value, a missing file) as one line on stderr and exit code 2, and ``destroy_node`` plus
``rclpy.try_shutdown`` whatever happens. The flag and a watchdog that bounds the way out (a hang in the spin call
or in the ROS teardown ends the process with a reason and the stacks) are :class:`~hyst_common.stopping.StopGuard`.

:class:`AtomicParametersNode` makes every parameter set all or nothing: rclpy's ``set_parameters`` (the method and
the ``~/set_parameters`` service) validates and applies each parameter alone, so ``[v_min=100, v_max=50]`` applied
``v_max=50`` next to a refused ``v_min``. Here the list is validated as one resulting configuration by the node's
on-set callback and applied whole or not at all (one result per parameter, all equal).
"""
from __future__ import annotations

import sys
import threading
from collections.abc import Callable, Mapping, Sequence
from typing import Any, TypeVar

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.exceptions import ParameterException, ParameterNotDeclaredException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.parameter_service import ParameterService
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions

from .errors import HystError
from .runtime import own_args
from .startup import end_quiet_start
from .stopping import StopGuard

__all__ = ["run_node", "AtomicParametersNode", "fp_range", "int_range", "STARTUP_ERRORS", "KEEP_ALL_RELIABLE",
           "diagnostic_status", "diagnostic_array"]

#: Every sample reaches every reader (a slow reliable reader slows the writer instead of losing samples): the
#: lockstep sim's ``/stage/state``, the bag recorder, test readers. ``depth`` only sizes the first allocation.
KEEP_ALL_RELIABLE = QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=1000, reliability=ReliabilityPolicy.RELIABLE)

#: What a node may raise while it starts because of what the user gave it: one line, exit 2.
STARTUP_ERRORS: tuple[type[BaseException], ...] = (HystError, ValueError, ParameterException)

#: The node type :func:`run_node` builds (its ``until`` and ``on_exit`` see that node).
NodeT = TypeVar("NodeT", bound=Node)


def fp_range(lo: float, hi: float) -> list[FloatingPointRange]:
    """``floating_point_range`` of a ParameterDescriptor (continuous)."""
    return [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]


def int_range(lo: int, hi: int) -> list[IntegerRange]:
    """``integer_range`` of a ParameterDescriptor (step 1)."""
    return [IntegerRange(from_value=int(lo), to_value=int(hi), step=1)]


def diagnostic_status(name: str, hardware_id: str, level: bytes, message: str,
                      values: Mapping[str, Any] | None = None) -> DiagnosticStatus:
    """One ``/diagnostics`` status; each value as text (floats to 6 significant digits, the rest by ``str``).

    ``level`` is ``DiagnosticStatus.OK``, ``WARN`` or ``ERROR``.
    """
    return DiagnosticStatus(name=name, hardware_id=hardware_id, level=level, message=message,
                            values=[KeyValue(key=str(k), value=f"{v:.6g}" if isinstance(v, float) else str(v))
                                    for k, v in (values or {}).items()])


def diagnostic_array(node: Node, statuses: Sequence[DiagnosticStatus]) -> DiagnosticArray:
    """The statuses stamped with the node's clock, ready to publish on ``/diagnostics``."""
    arr = DiagnosticArray(status=list(statuses))
    arr.header.stamp = node.get_clock().now().to_msg()
    return arr


class _AllOrNothingService(ParameterService):
    """The node's parameter services, ``set_parameters`` going through :meth:`AtomicParametersNode.set_parameters`."""

    def _set_parameters_callback(self, request, response):
        params, bad = _from_msgs(request.parameters)
        if bad:
            response.results = [SetParametersResult(successful=False, reason=bad)] * len(request.parameters)
            return response
        node = self._get_node()
        try:
            response.results = node.set_parameters(params)
        except ParameterNotDeclaredException:
            names = ", ".join(p.name for p in params if not node.has_parameter(p.name))
            response.results = [SetParametersResult(successful=False, reason=f"undeclared parameter(s): {names}; "
                                                    "none of this request applied")] * len(params)
        return response

    def _set_parameters_atomically_callback(self, request, response):
        params, bad = _from_msgs(request.parameters)
        if bad:
            response.result = SetParametersResult(successful=False, reason=bad)
            return response
        try:
            response.result = self._get_node().set_parameters_atomically(params)
        except ParameterNotDeclaredException as err:
            response.result = SetParametersResult(successful=False, reason=str(err))
        return response


def _from_msgs(msgs) -> tuple[list[Parameter], str]:
    """The request's parameters, or the reason one cannot be read: a value of an unknown type code raised inside
    rclpy's service callback and killed the node (exit 1, traceback)."""
    try:
        return [Parameter.from_parameter_msg(p) for p in msgs], ""
    except (ValueError, TypeError, AttributeError) as err:
        return [], f"malformed parameter in the request ({err}); none of this request applied"


class AtomicParametersNode(Node):
    """A :class:`rclpy.node.Node` whose parameter sets are all or nothing (see the module docstring)."""

    def __init__(self, node_name: str, **kwargs) -> None:
        services = kwargs.pop("start_parameter_services", True)
        super().__init__(node_name, start_parameter_services=False, **kwargs)
        if services:
            self._parameter_service = _AllOrNothingService(self)

    def declare_parameter(self, name: str, value: Any = None, descriptor: ParameterDescriptor | None = None,
                          ignore_override: bool = False) -> Parameter:
        """As rclpy's, but a whole number given for a floating-point parameter (``-p v_max:=100``, ``zeta1: 1`` in a
        params file) is that number as a float: rclpy refused it at start ("expecting type 'DOUBLE'"); and an
        empty list given for a list parameter is its default."""
        over = self._parameter_overrides.get(name)
        if isinstance(value, float) and over is not None and over.type_ == Parameter.Type.INTEGER:
            self._parameter_overrides[name] = Parameter(name, Parameter.Type.DOUBLE, float(over.value))
        if (isinstance(value, list) and value and all(isinstance(v, float) for v in value) and over is not None
                and over.type_ == Parameter.Type.INTEGER_ARRAY):  # ``amplitudes:=[1]``, as for a single number
            self._parameter_overrides[name] = Parameter(name, Parameter.Type.DOUBLE_ARRAY,
                                                        [float(v) for v in over.value])
        if isinstance(value, list) and over is not None and over.type_ == Parameter.Type.NOT_SET:
            # ``name: []`` in a params file: ROS cannot type an empty list and left the parameter unset, which
            # broke every "get all parameters" (a dump); the declared default stands (hyst's lists default to
            # none, ``[""]``)
            del self._parameter_overrides[name]
        return super().declare_parameter(name, value, descriptor, ignore_override)

    def _as_declared(self, p: Parameter) -> Parameter:
        """A whole number set for a declared floating-point parameter, as that float (see :meth:`declare_parameter`)."""
        if p.type_ == Parameter.Type.INTEGER and self.has_parameter(p.name) \
                and self.get_parameter(p.name).type_ == Parameter.Type.DOUBLE:
            return Parameter(p.name, Parameter.Type.DOUBLE, float(p.value))
        if p.type_ == Parameter.Type.INTEGER_ARRAY and self.has_parameter(p.name) \
                and self.get_parameter(p.name).type_ == Parameter.Type.DOUBLE_ARRAY:
            return Parameter(p.name, Parameter.Type.DOUBLE_ARRAY, [float(v) for v in p.value])
        return p

    def set_parameters_atomically(self, parameter_list: Sequence[Parameter]) -> SetParametersResult:
        """As rclpy's, whole numbers for floating-point parameters taken as floats (the atomic service too)."""
        return super().set_parameters_atomically([self._as_declared(p) for p in parameter_list])

    def set_parameters(self, parameter_list: Sequence[Parameter]) -> list[SetParametersResult]:
        """Validate ``parameter_list`` as one configuration and apply it whole or not at all (whole numbers for
        floating-point parameters taken as floats)."""
        result = self.set_parameters_atomically(list(parameter_list))
        return [result] * len(parameter_list)


def _executor(kind: str):
    if kind == "events":
        try:
            from rclpy.experimental import EventsExecutor  # optional in older rclpy
            return EventsExecutor()
        except ImportError:  # pragma: no cover - older rclpy
            pass
    return SingleThreadedExecutor()


def run_node(make: Callable[..., NodeT], args: Sequence[str] | None = None, *, prog: str, usage: str = "",
             executor: str = "events", until: Callable[[NodeT], bool] | None = None,
             on_exit: Callable[[NodeT, bool], int | None] | None = None,
             errors: tuple[type[BaseException], ...] = (),
             parse: Callable[[list[str]], Any] | None = None) -> int:
    """Run the node ``make()`` until a signal, ``until(node)`` or the context ends; return the exit code.

    Parameters
    ----------
    make : callable
        Builds the node (after ``rclpy.init``); start-up errors (:data:`STARTUP_ERRORS` and ``errors``) raised
        here become one line on stderr and exit code 2.
    args : sequence of str, optional
        ``sys.argv`` by default; ROS arguments (``--ros-args ...``) are rclpy's, anything else is refused.
    prog, usage : str
        Program name for messages, and the text ``--help`` prints (before ROS starts).
    executor : {"events", "single"}
        ``events``: rclpy's EventsExecutor (lowest per-message overhead; driven by ``spin_once``, which leaves on a
        stop request and runs timers); ``single``: the SingleThreadedExecutor.
    until : callable, optional
        Stop when it returns True (a node that finishes its work, e.g. an excitation).
    on_exit : callable, optional
        ``on_exit(node, stopped_by_signal)`` before the node is destroyed (flush, finalise a bag, ramp to a safe
        output), on every way out once the node is built — also when a callback raised (the error is then
        raised again after it, a bug's traceback is worth keeping). An int it returns is the exit code (the
        driver's 3: the safe output was not confirmed).
    errors : tuple of exception types
        Further start-up errors of the node's own package.
    parse : callable, optional
        For a node with its own command line (the bag recorder and player): ``parse(own_args)`` (argparse: it
        answers ``--help`` and refuses bad input with exit 2 itself) runs before ROS starts, and ``make`` is
        called with its result. Without it, any non-ROS argument is refused.
    """
    argv = list(sys.argv if args is None else args)
    own = own_args(argv[1:])
    parsed: tuple[Any, ...] = ()
    if parse is not None:
        parsed = (parse(own),)
    elif own:
        if set(own) & {"-h", "--help"}:
            print(usage)
            return 0
        print(f"{prog}: error: unexpected argument(s) {' '.join(own)}; settings are ROS parameters "
              "(--ros-args -p name:=value); see --help", file=sys.stderr)
        return 2
    end_quiet_start()  # the guard takes the signals from here
    guard = StopGuard(prog, install=threading.current_thread() is threading.main_thread())
    try:
        try:
            rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
        except RuntimeError as err:  # rclpy's UnknownROSArgsError and kin: a bad --ros-args section
            print(f"{prog}: error: ROS arguments not understood: {err}", file=sys.stderr)
            return 2
        node: NodeT | None = None
        exit_code = 0
        try:
            try:
                node = make(*parsed)
            except STARTUP_ERRORS + tuple(errors) as err:
                print(f"{prog}: error: {err}", file=sys.stderr)
                return 2
            ex = _executor(executor)
            ex.add_node(node)
            guard.phase("spin")
            try:
                while not guard.stopped and rclpy.ok() and not (until is not None and until(node)):
                    ex.spin_once(timeout_sec=0.1)
            except (KeyboardInterrupt, ExternalShutdownException):
                guard.stopped = True
            finally:  # also when a callback raised: the driver must still ramp to its safe output
                guard.phase("exit")
                if on_exit is not None:
                    code = on_exit(node, guard.stopped)
                    exit_code = code if isinstance(code, int) and not isinstance(code, bool) else 0
                guard.phase("teardown")
            ex.remove_node(node)
            ex.shutdown()
        finally:
            guard.phase("teardown")
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
    finally:
        guard.close(exiting=args is None)  # as a console script (sys.argv), the process ends next
    return exit_code
