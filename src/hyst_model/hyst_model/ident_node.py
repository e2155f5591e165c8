"""``hyst_ident_node``: refit the stage model from recorded bags and hand it to the controller.

Work is timer driven. At start the bags in ``bags`` are queued; every ``poll_period`` the folder ``watch_dir`` (if
set) is scanned for new rosbag2 directories or ``.mcap`` files that have not changed for ``settle_time`` seconds
(a recorder still writing is left alone). Each bag is fitted in a worker thread (the node keeps answering its
parameter services), then

* the params file ``params_file`` is written atomically (an existing file the node did not write itself is only
  replaced with ``overwrite: true``: without it such a file is refused at start and when set, and one that appears
  later is left alone when a fit would write it; a bag the node fits is never replaced),
* a JSON summary is published on ``~/fit_result`` (``std_msgs/String``, transient local),
* with ``controller_node`` set (e.g. ``/hyst_controller``) the ``model.*`` parameters are pushed to that node
  through its parameter service (``AsyncParameterClient.set_parameters_atomically``: all or nothing).

A bad bag is logged and skipped; the node carries on. Parameters are declared with descriptors and ranges,
validated in the on-set callback and applied by swapping a frozen config.
"""
from __future__ import annotations

import json
import os
import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path

from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.exceptions import ParameterUninitializedException
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import DurabilityPolicy, QoSProfile
from std_msgs.msg import String

from hyst_common.node import AtomicParametersNode, fp_range, int_range, run_node

from .core.mbw import PARAM_NAMES
from .errors import HystError
from .identify.methods import METHODS

__all__ = ["IdentConfig", "IdentNode", "main", "fit_bag", "controller_parameters"]


USAGE = (
    'hyst_ident_node: refit the stage model from rosbag2 recordings (given bags or a watched folder), write the\n'
    'ROS 2 params file and optionally push model.* to a running controller node.\n'
    '\n'
    'usage: hyst_ident_node [--ros-args -p bags:=[...] -p watch_dir:=DIR -p params_file:=P '
    '-p controller_node:=/hyst_controller ...]\n'
    'Parameters are documented in the module docstring and README.'
)


def _listed(v) -> tuple[str, ...]:
    """A string-list parameter's items: ``[""]`` (the declared none) and unset are empty."""
    return tuple(str(x) for x in (v or ()) if str(x))


#: The effect settings as this node's parameters call them (the messages of :func:`~.spec.parse_effect_config`).
_NAMES = ("effect_config", "effects")


@dataclass(frozen=True)
class IdentConfig:
    """Validated node settings (see the parameter descriptions in :meth:`IdentNode._declare`)."""

    bags: tuple[str, ...] = ()
    watch_dir: str = ""
    poll_period: float = 2.0
    settle_time: float = 2.0
    topic: str = "/stage/state"
    model: str = "mbw"
    effects: tuple[str, ...] = ()
    method: str = "fast"
    seed: int = -1
    val_fraction: float = 0.25
    params_file: str = ""
    overwrite: bool = False
    controller_node: str = ""
    push_timeout: float = 5.0
    gaps: str = "auto"
    admissible: bool = False
    effect_config: tuple[str, ...] = ()

    def _check_params_file(self) -> None:
        """Refused now, not after a fit: a directory, or one of the bags (or a file in one) even with ``overwrite``
        (a 1.2 MB recording became a 1 kB params file). An existing file is :func:`_refuse_existing`'s: it depends
        on what the node wrote itself, which a configuration does not know."""
        target = os.path.realpath(self.params_file)
        if os.path.isdir(target):
            raise ValueError(f"params_file {self.params_file!r} is a directory; give a file path")
        for bag in self.bags:
            b = os.path.realpath(bag)
            if target == b or target.startswith(b + os.sep):
                raise ValueError(f"params_file {self.params_file!r} would replace the recording {bag!r}")

    def validate(self) -> "IdentConfig":
        from .models import BASE_MODELS
        if self.model not in BASE_MODELS:
            raise ValueError(f"model must be one of {', '.join(sorted(BASE_MODELS))}")
        from .io.regular import GAP_POLICIES
        if self.gaps not in GAP_POLICIES:
            raise ValueError(f"gaps must be one of {', '.join(GAP_POLICIES)}")
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {', '.join(METHODS)}")
        if self.admissible and self.model == "pi":
            raise ValueError("admissible applies to mbw and bw (Remark 4.1 and their rate terms), not pi")
        self.check_effect_config()  # the effects and their configuration, checked before any bag is fitted
        if self.watch_dir and not Path(self.watch_dir).is_dir():
            raise ValueError(f"watch_dir {self.watch_dir!r} is not a directory")
        if self.params_file and not Path(self.params_file).parent.is_dir():
            raise ValueError(f"directory of params_file {self.params_file!r} does not exist")
        if self.params_file:
            self._check_params_file()
        if not self.topic.startswith("/"):
            raise ValueError("topic must be absolute (start with /)")
        if self.controller_node and not self.controller_node.startswith("/"):
            raise ValueError("controller_node must be a fully qualified node name such as /hyst_controller")
        if self.controller_node:  # /bad-name passed and then killed the node when the push made its client
            from rclpy.exceptions import InvalidServiceNameException
            from rclpy.validate_full_topic_name import validate_full_topic_name
            try:
                validate_full_topic_name(f"{self.controller_node}/set_parameters", is_service=True)
            except InvalidServiceNameException as err:
                raise ValueError(f"controller_node {self.controller_node!r} is not a valid ROS node name (letters, "
                                 "digits and underscores, each part not starting with a digit)") from err
        return self

    def check_effect_config(self) -> None:
        """Refuse (ValueError, with the reason) an ``effect_config`` item that is not ``EFFECT.KEY=VALUE`` for a
        listed effect, or a model that cannot be built with it (an unknown effect or form: the effect's reason)."""
        from .errors import HystError
        from .spec import build_model, parse_effect_config
        try:
            user = parse_effect_config(self.effect_config, self.effects, names=_NAMES)
            build_model(self.model, self.effects, {"dt": 1e-3, "u_scale": 1.0, "y_scale": 1.0, **user})
        except HystError as err:
            raise ValueError(str(err)) from err


def fit_bag(path: str, cfg: IdentConfig) -> tuple[dict, object, object, float]:
    """Fit ``cfg.model`` (+ effects) to one bag; returns ``(summary, model, result, dt)``. Pure: no ROS."""
    from .effects.settle import settle_result
    from .identify import fit
    from .identify.admissible import check_admissible, constrain, constrained_summary
    from .identify.input_range import identified_range
    from .io import read_state_bag, regularise
    from .models import data_config
    from .spec import build_model
    # Lockstep bags repeat sample 0, realtime bags miss periods: made regular as `hyst fit --gaps` does.
    rec, notes = regularise(read_state_bag(path, cfg.topic), cfg.gaps)
    rec.check()
    split = None
    if cfg.val_fraction > 0:  # the hold-out hyst fit and hyst diagnose use: interleaved blocks, not the tail
        from .diagnose.diagnose import BLOCKS  # (the tail after an excitation is rest: 2.6 nm there, 76 nm in blocks)
        from .identify import block_mask
        split = block_mask(len(rec), cfg.val_fraction, BLOCKS, rec.u)
    config = dict(data_config(rec.u, rec.y), dt=rec.dt)
    if cfg.effects:  # each effect's settings from the samples the fit scores, then the user's: as hyst fit does
        from .spec import effect_settings, parse_effect_config
        config.update(effect_settings(cfg.effects, rec.t, rec.u, rec.y, split))
        config.update(parse_effect_config(cfg.effect_config, cfg.effects, names=_NAMES))  # checked when it was set
    model = build_model(cfg.model, cfg.effects, config)
    seed = cfg.seed
    if seed < 0 and METHODS[cfg.method].seeded:  # drawn and kept in the summary: the fit can be repeated
        import secrets
        seed = secrets.randbelow(2 ** 31)
    res = fit(model, rec.t, rec.u, rec.y, method=cfg.method, seed=None if seed < 0 else seed, split=split)
    res = settle_result(model, res, rec.t, rec.u)  # no stop where the record shows none, as hyst fit
    constrained = None
    if cfg.admissible:  # as hyst fit --admissible: Remark 4.1 and passive rate terms, at a stated cost
        con = constrain(model, rec.t, rec.u, rec.y, res.theta, split)
        if con is not None:  # the free fit's violations for the summary, as hyst fit's JSON names them
            constrained = constrained_summary(res.rmse, check_admissible(model, res.theta).violations, con.rmse)
            res = settle_result(model, con, rec.t, rec.u)
    # Remark 4.1, parameters on their bounds and a divergence probe on the record's input range, as hyst fit
    # reports them; the model is still written and pushed (the controller probes it against its own limits).
    adm = check_admissible(model, res.theta, record=(rec.t, rec.u, rec.y))
    summary = {"bag": str(path), "model": cfg.model, "effects": list(cfg.effects), "method": cfg.method,
               "rmse": res.rmse, "rmse_train": res.rmse_train, "seconds": res.seconds, "samples": len(rec),
               "params": res.params, "dt": rec.dt, "data_notes": notes, **identified_range(rec.u, rec.y),
               "split": res.split, **({"seed": seed} if seed >= 0 else {}),
               "admissibility": adm.to_json(), "constrained": constrained}
    return summary, model, res, rec.dt


#: The command line's options in the shared readers' messages, as this node's parameters.
_OPTION_AS_PARAMETER = ((r"--gaps (\w+)", r"gaps:=\1"), (r"--gaps\b", "the gaps parameter"),
                        (r"--topic (\S+)", r"topic:=\1"), (r"--topic\b", "the topic parameter"),
                        (r"--force\b", "overwrite:=true"))


def _as_parameters(message: str, bag: str) -> str:
    """A reader's error in this node's terms: its parameters for the CLI's options, the bag named once."""
    import re
    for opt, par in _OPTION_AS_PARAMETER:
        message = re.sub(opt, par, message)
    for prefix in (f"{bag}: ", f"{os.path.abspath(bag)}: "):
        if message.startswith(prefix):
            message = message[len(prefix):]
    return message


def controller_parameters(model, theta, dt: float) -> list[Parameter]:
    """``model.*`` parameters the controller node declares: the MBW (BW is MBW with zero rate terms), the scales,
    ``model.dt`` and, for a model with effects, ``model.effects`` with every effect parameter and configuration key
    (the controller compensates those it can invert and reports the rest).

    Every one is pushed, ``model.dt`` and the scales included, so the controller can refuse a model identified
    at another sample rate (the MBW recursion is per sample) instead of silently running it at its own rate.
    """
    base = getattr(model, "base", model)
    if base.name not in ("mbw", "bw"):
        raise HystError(f"the controller inverts MBW; a {base.name!r} model cannot be pushed")
    effects = [e.name for e in getattr(model, "effects", [])]
    if base.name == "bw" and effects:
        raise HystError("the controller inverts MBW: a bw model with effects cannot be pushed (refit with mbw)")
    values = dict(zip(PARAM_NAMES, (0.0,) * 8))
    values.update(model.unpack(theta))
    cfg = model.config()
    values.update({k: float(v) for k, v in cfg.items() if k in ("u_scale", "y_scale")})
    out = [Parameter("model.base", Parameter.Type.STRING, "mbw")]
    out += [Parameter(f"model.{k}", Parameter.Type.DOUBLE, float(values[k]))
            for k in PARAM_NAMES + ("offset", "u_scale", "y_scale")]
    out.append(Parameter("model.dt", Parameter.Type.DOUBLE, float(dt)))
    out.append(Parameter("model.effects", Parameter.Type.STRING_ARRAY, effects or [""]))
    for e in getattr(model, "effects", []):
        if not type(e).__module__.startswith("hyst_model.effects."):
            continue  # a user effect: the controller does not declare its keys, it names the effect as unused
        for p in e.params():
            out.append(Parameter(f"model.{e.name}.{p.name}", Parameter.Type.DOUBLE,
                                 float(values[f"{e.name}.{p.name}"])))
        for k, v in e.config().items():
            kind = Parameter.Type.STRING if isinstance(v, str) else Parameter.Type.DOUBLE
            out.append(Parameter(f"model.{e.name}.{k}", kind, v if isinstance(v, str) else float(v)))
    return out


def _refuse_existing(cfg: IdentConfig, written_by_me: set[str]) -> None:
    """An existing params_file the node did not write, without ``overwrite``: refused at start (and when set), not
    after the first fit as before, with this node's own words (it said "use --force")."""
    if cfg.params_file and not cfg.overwrite:
        target = os.path.abspath(cfg.params_file)
        if os.path.exists(target) and target not in written_by_me:
            raise ValueError(f"params_file {cfg.params_file!r} exists; set overwrite:=true to replace it")


class IdentNode(AtomicParametersNode):
    """Refits the stage model from bags; see the module docstring."""

    def __init__(self, **kwargs):
        super().__init__("hyst_ident_node", **kwargs)
        self._declare()
        try:
            self._cfg = self._read().validate()
            self._written_by_me: set[str] = set()
            _refuse_existing(self._cfg, self._written_by_me)
        except ValueError as err:
            raise HystError(f"invalid parameters: {err}") from err
        self.add_on_set_parameters_callback(self._on_set)
        self._queue: list[str] = list(self._cfg.bags)
        self._seen: set[str] = set(os.path.abspath(b) for b in self._cfg.bags)
        self._sizes: dict[str, tuple[int, float]] = {}
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="hyst_fit")
        self._job: Future | None = None
        self._job_bag = ""
        self._client: AsyncParameterClient | None = None
        self._client_name = ""
        self._pending: tuple | None = None  # (params, deadline_s, summary): waiting for the controller service
        self.results: list[dict] = []
        qos = QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self._pub = self.create_publisher(String, "~/fit_result", qos)
        self._timer = self.create_timer(0.1, self._tick)
        self._last_scan = -1e9
        self.get_logger().info(f"ready: {len(self._queue)} bag(s) queued"
                               + (f", watching {self._cfg.watch_dir}" if self._cfg.watch_dir else ""))

    # parameters ------------------------------------------------------------------------------------------
    def _declare(self) -> None:
        d = self.declare_parameter
        S = [""]  # none: a typed list without a value breaks a parameter dump (and ROS cannot type [])
        d("bags", S, ParameterDescriptor(description="bags (rosbag2 dirs or .mcap files) to fit at start"))
        d("watch_dir", "", ParameterDescriptor(description="folder watched for new bags ('' = off)"))
        d("poll_period", 2.0, ParameterDescriptor(description="folder scan period (s)",
                                                  floating_point_range=fp_range(0.05, 600)))
        d("settle_time", 2.0, ParameterDescriptor(description="a bag is complete when unchanged this long (s)",
                                                  floating_point_range=fp_range(0.0, 3600)))
        d("topic", "/stage/state", ParameterDescriptor(description="JointState topic with the stage state"))
        d("model", "mbw", ParameterDescriptor(description="base model: mbw | bw | pi"))
        d("effects", S, ParameterDescriptor(description="effects composed onto the base (hyst_model.effects)"))
        d("method", "fast", ParameterDescriptor(description="identifier: " + " | ".join(METHODS)))
        d("seed", -1, ParameterDescriptor(description="random seed for epso (-1 = random)",
                                          integer_range=int_range(-1, 2**31 - 1)))
        d("val_fraction", 0.25, ParameterDescriptor(description="held-out share of each bag for validation, in "
                                                    "interleaved blocks as hyst fit (0 = none)",
                                                    floating_point_range=fp_range(0.0, 0.9)))
        d("params_file", "", ParameterDescriptor(description="params file to write after each fit ('' = none)"))
        d("overwrite", False, ParameterDescriptor(
            description="replace a params file that existed before this node wrote it"))
        d("controller_node", "", ParameterDescriptor(
            description="push model.* to this node after each fit, e.g. /hyst_controller ('' = off)"))
        d("push_timeout", 5.0, ParameterDescriptor(description="wait this long for the controller's parameter "
                                                               "service (s)", floating_point_range=fp_range(0.1, 600)))
        d("gaps", "auto", ParameterDescriptor(
            description="irregular stamps in a bag: auto (collapse lockstep repeats, bridge up to 10 missed periods "
                        "with the input held, else keep the longest segment) | bridge | longest | refuse"))
        d("effect_config", S, ParameterDescriptor(
            description="effect configuration, EFFECT.KEY=VALUE items as hyst fit --config takes them, e.g. "
                        "creep.form=lags or dynamics.structure=feedback (hyst diagnose writes the ones it chose)"))
        d("admissible", False, ParameterDescriptor(
            description="refit a model outside Remark 4.1 or with a negative rate term (psi < 0) constrained, as "
                        "hyst fit --admissible: the fit the controllers can also run open loop"))

    def _read(self, changes: dict | None = None) -> IdentConfig:
        def get(name):
            if changes and name in changes:
                return changes[name]
            try:
                return self.get_parameter(name).value
            except ParameterUninitializedException:  # typed string arrays start unset: empty
                return None
        return IdentConfig(
            bags=_listed(get("bags")), watch_dir=str(get("watch_dir")), poll_period=float(get("poll_period")),
            settle_time=float(get("settle_time")), topic=str(get("topic")), model=str(get("model")),
            effects=_listed(get("effects")), method=str(get("method")), seed=int(get("seed")),
            val_fraction=float(get("val_fraction")), params_file=str(get("params_file")),
            overwrite=bool(get("overwrite")), controller_node=str(get("controller_node")),
            push_timeout=float(get("push_timeout")), gaps=str(get("gaps")), admissible=bool(get("admissible")),
            effect_config=_listed(get("effect_config")))

    def _on_set(self, params) -> SetParametersResult:
        try:
            cfg = self._read({p.name: p.value for p in params}).validate()
            if (cfg.params_file, cfg.overwrite) != (self._cfg.params_file, self._cfg.overwrite):
                _refuse_existing(cfg, self._written_by_me)  # judged when it changes, not on every set
        except (ValueError, TypeError) as err:
            return SetParametersResult(successful=False, reason=str(err))
        new_bags = [b for b in cfg.bags if os.path.abspath(b) not in self._seen]
        self._cfg = replace(cfg)
        for b in new_bags:  # bags set at run time are queued too
            self._seen.add(os.path.abspath(b))
            self._queue.append(b)
        return SetParametersResult(successful=True)

    # work --------------------------------------------------------------------------------------------------
    def _scan(self) -> None:
        cfg = self._cfg
        if not cfg.watch_dir:
            return
        now = self.get_clock().now().nanoseconds * 1e-9
        if now - self._last_scan < cfg.poll_period:
            return
        self._last_scan = now
        try:
            entries = sorted(Path(cfg.watch_dir).iterdir())
        except OSError as err:
            self.get_logger().warning(f"cannot scan {cfg.watch_dir}: {err}")
            return
        for p in entries:
            key = str(p.resolve())
            if key in self._seen or p.name.startswith("."):
                continue
            if not ((p.is_dir() and (p / "metadata.yaml").exists()) or p.suffix == ".mcap"):
                continue
            files = [p] if p.is_file() else [f for f in p.iterdir() if f.is_file()]
            size = sum(f.stat().st_size for f in files)
            mtime = max(f.stat().st_mtime for f in files)
            if self._sizes.get(key, (None,))[0] != size or time.time() - mtime < cfg.settle_time:
                self._sizes[key] = (size, mtime)
                continue
            self._seen.add(key)
            self._queue.append(str(p))

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _tick(self) -> None:
        self._scan()
        self._try_push()
        if self._job is not None:
            if not self._job.done():
                return
            job, bag, self._job = self._job, self._job_bag, None
            try:
                summary, model, res, dt = job.result()
            except HystError as err:
                why = _as_parameters(str(err), bag)
                self.get_logger().error(f"{bag}: {why}")
                self._publish({"bag": bag, "error": why})
                return
            except Exception as err:  # noqa: BLE001 - a broken bag or model must not take the node down
                self.get_logger().error(f"{bag}: fit failed ({type(err).__name__}: {err})")
                self._publish({"bag": bag, "error": f"{type(err).__name__}: {err}"})
                return
            self._deliver(summary, model, res, dt)
        if self._queue and self._job is None:
            bag = self._queue.pop(0)
            self._job_bag = bag
            self.get_logger().info(f"fitting {bag}")
            self._job = self._pool.submit(fit_bag, bag, self._cfg)

    def _deliver(self, summary: dict, model, res, dt: float) -> None:
        cfg = self._cfg
        self.get_logger().info(f"{summary['bag']}: validation RMSE {res.rmse * 1e9:.2f} nm "
                               f"(train {res.rmse_train * 1e9:.2f} nm, {res.seconds:.2f} s)")
        adm = summary.get("admissibility") or {}
        if adm.get("bounded") is False or adm.get("remark_4_1") is False:
            self.get_logger().warning(f"{summary['bag']}: {adm.get('controllers', '')}")
        if cfg.params_file:
            from .io import spec_from_model, write_params
            target = os.path.abspath(cfg.params_file)
            force = cfg.overwrite or target in self._written_by_me
            # the provenance hyst fit --out writes (the notes on the bag, the split, the identified ranges, what
            # the controllers can do with it)
            prov = {"method": cfg.method, "rmse": res.rmse, "rmse_train": res.rmse_train, "data": summary["bag"],
                    "split": res.split, "seconds": round(res.seconds, 3), "samples": summary["samples"],
                    **({"data_notes": "; ".join(summary["data_notes"])} if summary.get("data_notes") else {}),
                    **({"seed": summary["seed"]} if "seed" in summary else {}),
                    **({"controllers": adm["controllers"]} if adm.get("controllers") else {}),
                    **{k: summary[k] for k in ("u_min", "u_max", "y_min", "y_max") if k in summary}}
            try:
                write_params(target, spec_from_model(model, res.theta, fit=prov, dt=dt), force=force)
                self._written_by_me.add(target)
                summary["params_file"] = target
            except HystError as err:
                why = str(err).replace("; use --force to overwrite it", "")  # a CLI option, not this node's
                self.get_logger().error(f"not written: {why} (set overwrite:=true to replace it)")
                summary["params_file_error"] = str(err)
        if cfg.controller_node:
            self._push(model, res.theta, dt, summary)
        self._publish(summary)

    def _push(self, model, theta, dt: float, summary: dict) -> None:
        cfg = self._cfg
        try:
            params = controller_parameters(model, theta, dt)
        except HystError as err:
            self.get_logger().warning(f"not pushed: {err}")
            summary["push"] = f"skipped: {err}"
            return
        if self._client is None or self._client_name != cfg.controller_node:
            self._client = AsyncParameterClient(self, cfg.controller_node)
            self._client_name = cfg.controller_node
        summary["push"] = "pending"
        if self._pending is not None:  # the newest model goes; the one it replaces is said, not dropped silently
            old = self._pending[2]
            self.get_logger().warning(f"{old}: not pushed, superseded by {summary['bag']} before "
                                      f"{self._client_name} could be reached")
            self._publish({"bag": old, "push": f"superseded by {summary['bag']}"})
        self._pending = (params, self._now() + cfg.push_timeout, summary["bag"])
        self._try_push()

    def _try_push(self) -> None:
        """Send a pending push once the controller's parameter service is discovered (timer driven, no blocking)."""
        if self._pending is None or self._client is None:
            return
        params, deadline, bag = self._pending
        node_name = self._client_name
        if not self._client.services_are_ready():
            if self._now() > deadline:
                self._pending = None
                self.get_logger().warning(f"{node_name} parameter service not available; model not pushed")
                self._publish({"bag": bag, "push": "controller not available"})
            return
        self._pending = None
        fut = self._client.set_parameters_atomically(params)
        summary = {"bag": bag}

        def done(f):
            try:
                r = f.result().result
                ok = r.successful
                if ok:
                    self.get_logger().info(f"pushed model to {node_name}")
                else:  # the controller runs on its old model: the user must hear it
                    self.get_logger().error(f"{node_name} rejected the model: {r.reason}")
                self._publish({"bag": summary["bag"], "push": "accepted" if ok else f"rejected: {r.reason}"})
            except Exception as err:  # noqa: BLE001 - service went away mid-call
                self.get_logger().error(f"push to {node_name} failed: {err}")
        fut.add_done_callback(done)

    def _publish(self, obj: dict) -> None:
        self.results.append(obj)
        self._pub.publish(String(data=json.dumps(obj, default=float)))

    def destroy_node(self):
        self._pool.shutdown(wait=False, cancel_futures=True)
        return super().destroy_node()


def main(args=None) -> int:
    """Console script ``hyst_ident_node``."""
    return run_node(IdentNode, args, prog="hyst_ident_node", usage=USAGE, executor="single")


if __name__ == "__main__":
    main()
