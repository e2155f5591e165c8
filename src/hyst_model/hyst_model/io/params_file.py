"""The params file: a ROS 2 parameters YAML that describes one fitted model (docs/ARCHITECTURE.md).

::

    /**:
      ros__parameters:
        model:
          base: mbw
          effects: [creep]     # omitted when there are none: ROS cannot type an empty list
          zeta1: 0.4029        # every Param.name; effect params nested: creep.gain -> creep: {gain: ...}
          ...
          offset: 0.0          # m
          u_scale: 15.0        # config (not fitted)
          y_scale: 5.42e-06
          dt: 0.0005
        fit: {method: fast, rmse: 1.2e-08, rmse_train: 1.1e-08, data: bags/x}

The controller node loads it with ``--ros-args --params-file P``; ``hyst simulate``, the sim and the
identification node read it with :func:`read_params`. Writes are atomic (temporary file + rename in the same
directory) and never replace an existing file unless ``force=True``; without ``force`` the final link is
``os.link``, which fails if the target appeared meanwhile, so even a race cannot clobber a file.
"""
from __future__ import annotations

import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from .modes import mkstemp_user
from ..errors import HystError, ParamsError
from ..model import Model

#: A number as YAML 1.2 reads it, which PyYAML's YAML 1.1 leaves a string without a decimal point (``1e-6``).
NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")

__all__ = ["ParamsSpec", "read_params", "write_params", "spec_from_model", "to_yaml", "flatten", "nest", "NUMBER"]


def flatten(d: Mapping, prefix: str = "") -> dict:
    """``{"creep": {"gain": 1}}`` → ``{"creep.gain": 1}``."""
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, Mapping):
            out.update(flatten(v, key + "."))
        else:
            out[key] = v
    return out


def nest(d: Mapping) -> dict:
    """Inverse of :func:`flatten`."""
    out: dict = {}
    for k, v in d.items():
        parts = str(k).split(".")
        cur = out
        for p in parts[:-1]:
            cur = cur.setdefault(p, {})
        cur[parts[-1]] = v
    return out


@dataclass
class ParamsSpec:
    """A model spec as stored in a params file.

    Attributes
    ----------
    base : str
        Key in :data:`hyst_model.models.BASE_MODELS`.
    effects : list of str
        Keys in ``hyst_model.effects.EFFECTS``, in order.
    values : dict
        Fitted value per ``Param.name`` (dotted for effect parameters), SI units.
    config : dict
        Non-fitted configuration (``u_scale``, ``y_scale``, ``dt``, ...).
    fit : dict
        Provenance (method, rmse, rmse_train, data, ...); informative only.
    """

    base: str
    effects: list = field(default_factory=list)
    values: dict = field(default_factory=dict)
    config: dict = field(default_factory=dict)
    fit: dict = field(default_factory=dict)

    def model(self) -> Model:
        """Rebuild the model (:func:`hyst_model.spec.build_model`)."""
        from ..spec import build_model
        return build_model(self.base, self.effects, self.config)

    def theta(self, model: Model | None = None) -> np.ndarray:
        """Packed parameter vector for ``model`` (default :meth:`model`); every parameter must be present."""
        model = model or self.model()
        legacy: dict[str, float] = getattr(model, "legacy_values", dict)()  # added since older files were written
        values = {**{k: v for k, v in legacy.items() if k not in self.values}, **self.values}
        missing = [n for n in model.names if n not in values]
        if missing:
            raise ParamsError(f"params file lacks model parameter(s) {', '.join(missing)}")
        return model.pack(values)

    def parameters(self) -> dict:
        """Flat ROS parameter names → values (``model.zeta1``, ``model.creep.gain``, ...), as a node declares."""
        out = {"model.base": self.base, "model.effects": list(self.effects)}
        out.update({f"model.{k}": v for k, v in {**self.config, **self.values}.items()})
        return out


def spec_from_model(model: Model, theta, *, fit: Mapping | None = None, dt: float | None = None) -> ParamsSpec:
    """A :class:`ParamsSpec` for ``model`` at packed ``theta``."""
    base = getattr(model, "base", model)
    effects = [getattr(e, "name", str(e)) for e in getattr(model, "effects", [])]
    config = dict(model.config())
    if dt is not None:  # a median of float differences: 0.0009999999999998899 is 1 ms, written as such
        config["dt"] = float(f"{float(dt):.12g}")
    values = {k: float(v) for k, v in model.unpack(np.asarray(theta, dtype=np.float64)).items()}
    return ParamsSpec(str(base.name), effects, values, config, dict(fit or {}))


def _plain(v):
    if isinstance(v, (np.floating, float)):
        return float(v)
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    return v


def to_yaml(spec: ParamsSpec, node: str = "/**") -> str:
    """The YAML text of a params file. Numbers in ``values``/``config`` are written as floats (ROS types them)."""
    model: dict = {"base": spec.base}
    if spec.effects:  # an empty list has no ROS type (rcl reads it as NOT_SET, which nodes cannot declare)
        model["effects"] = list(spec.effects)
    model.update(nest({k: (float(v) if isinstance(v, (int, float, np.number)) and not isinstance(v, bool) else
                           _plain(v)) for k, v in {**spec.config, **spec.values}.items()}))
    doc = {node: {"ros__parameters": {"model": model}}}
    if spec.fit:
        doc[node]["ros__parameters"]["fit"] = {k: _plain(v) for k, v in spec.fit.items()}
    return yaml.safe_dump(doc, sort_keys=False, default_flow_style=False)


def write_params(path: str | Path, spec: ParamsSpec, *, force: bool = False, node: str = "/**") -> Path:
    """Write ``spec`` to ``path`` atomically.

    Raises
    ------
    ParamsError
        ``path`` exists and ``force`` is false, or its directory does not exist.
    """
    from .outputs import check_output
    path = check_output(path, force=force, what="params file")
    parent = path.parent if str(path.parent) else Path(".")
    text = to_yaml(spec, node)
    try:
        fd, tmp = mkstemp_user(prefix=f".{path.name}.", suffix=".tmp", dir=parent)  # the user's umask, not 0600
    except OSError as err:
        raise ParamsError(f"cannot write {path}: {err.strerror or err}") from err
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        if force:
            os.replace(tmp, path)
        else:
            try:
                os.link(tmp, path)  # atomic and fails if the target exists: no clobbering even in a race
            except FileExistsError:
                raise ParamsError(f"{path} exists; use --force to overwrite it") from None
            os.unlink(tmp)
    except OSError as err:
        raise ParamsError(f"cannot write {path}: {err.strerror or err}") from err
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


def _check_effect_keys(path: Path, effects: list, flat: Mapping) -> None:
    """Refuse a key inside a listed effect's section that is none of its parameters or settings (over its
    variants, so a file holding every configuration's keys — a node's parameter dump — still reads): a mistyped
    ``drift.sid: sensor`` was read without a word and the effect ran with its default."""
    from ..effects.compose import effect_keys
    for name in effects:
        keys = effect_keys(name, flat)
        if keys is None:
            continue
        known = keys[0] | keys[1]
        bad = sorted(k for k in flat if k.startswith(name + ".") and k[len(name) + 1:] not in known)
        if bad:
            raise ParamsError(f"{path}: model.{bad[0]} is none of {name}'s parameters or settings "
                              f"({', '.join(sorted(known))})")


def _one_line(err: BaseException) -> str:
    """A reader's error in one line: YAML's problem and where (``line 3, column 12``), not its six-line excerpt
    cut at 200 characters."""
    mark = getattr(err, "problem_mark", None)
    problem = getattr(err, "problem", None)
    if problem and mark is not None:
        return f"{type(err).__name__}: {problem} at line {mark.line + 1}, column {mark.column + 1}"
    text = " ".join(str(err).split())
    return f"{type(err).__name__}: {text[:160]}{'...' if len(text) > 160 else ''}"


def read_params(path: str | Path) -> ParamsSpec:
    """Read a params file written by :func:`write_params` (or by hand in the same layout).

    The first top-level node entry with ``ros__parameters.model`` is used. Keys of ``model`` that are parameters
    of the rebuilt model become ``values``; the rest (``u_scale``, ``y_scale``, ``dt``, ...) become ``config``.

    Raises
    ------
    ParamsError
        Missing or unreadable file, no ``model`` section, unknown base model or effect, missing parameters, a key
        in an effect's section that is none of its parameters or settings.
    """
    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ParamsError(f"{path}: no such params file") from None
    except (OSError, yaml.YAMLError, UnicodeDecodeError, RecursionError) as err:  # binary, garbage, unreadable
        raise ParamsError(f"{path}: cannot read params file ({_one_line(err)})") from err
    if not isinstance(doc, Mapping):
        raise ParamsError(f"{path}: not a ROS 2 parameters file (expected '/**: ros__parameters: model: ...')")
    section = None
    for node, body in doc.items():
        if isinstance(body, Mapping) and isinstance(body.get("ros__parameters"), Mapping) \
                and isinstance(body["ros__parameters"].get("model"), Mapping):
            section = body["ros__parameters"]
            break
    if section is None:
        raise ParamsError(f"{path}: no 'ros__parameters: model:' section")
    model = dict(section["model"])
    base = model.pop("base", None)
    if not isinstance(base, str):
        raise ParamsError(f"{path}: model.base missing (e.g. 'mbw')")
    effects = model.pop("effects", []) or []
    if isinstance(effects, str):
        effects = [e.strip() for e in effects.split(",") if e.strip()]
    if not isinstance(effects, list) or not all(isinstance(e, str) for e in effects):
        raise ParamsError(f"{path}: model.effects must be a list of effect names, not {effects!r}")
    fit = section.get("fit") or {}
    if not isinstance(fit, Mapping):
        raise ParamsError(f"{path}: 'fit' must be a mapping of provenance keys, not {type(fit).__name__}")
    # YAML 1.1 (PyYAML) reads 1e-6 (no decimal point) as a string: "lacks zeta2" for a key that is there
    flat = {k: (float(v) if isinstance(v, str) and NUMBER.fullmatch(v.strip()) else v)
            for k, v in flatten(model).items()}
    for k, v in flat.items():
        if isinstance(v, bool) or not isinstance(v, (int, float, str)):
            raise ParamsError(f"{path}: model.{k} has an unsupported value {v!r}")
    spec = ParamsSpec(base, list(effects), {}, {}, dict(fit))
    numeric = {k: v for k, v in flat.items() if isinstance(v, (int, float))}
    spec.config = {k: v for k, v in flat.items()}
    try:
        m = spec.model()
    except HystError:
        raise
    except (ValueError, TypeError) as err:
        raise ParamsError(f"{path}: invalid model configuration ({err})") from err
    names = set(m.names)
    _check_effect_keys(path, spec.effects, flat)
    words = sorted(k for k in names if isinstance(flat.get(k), str))
    if words:
        raise ParamsError(f"{path}: model.{words[0]} is not a number ({flat[words[0]]!r})")
    known = names | set(m.config()) | {"dt"}  # a listed effect's own keys are _check_effect_keys' to judge
    unknown = sorted(k for k in flat if k not in known and k.split(".", 1)[0] not in spec.effects)
    if unknown:  # a typo (zetta1) or an effect's section without the effect listed: silently unused before
        k = unknown[0]
        head = k.split(".", 1)[0]
        hint = (f"effect {head!r} is not in model.effects ({', '.join(spec.effects) or 'none'})" if "." in k else
                f"not a parameter or setting of {'+'.join([base, *spec.effects])} (parameters: {', '.join(m.names)})")
        raise ParamsError(f"{path}: model.{k}: {hint}; remove or correct it"
                          + (f" (and {len(unknown) - 1} more)" if len(unknown) > 1 else ""))
    spec.values = {k: float(v) for k, v in numeric.items() if k in names}
    spec.config = {k: v for k, v in flat.items() if k not in names}
    bad = [k for k, v in spec.values.items() if not np.isfinite(v)]
    if bad:
        raise ParamsError(f"{path}: non-finite value for {', '.join(bad)}")
    _check_ranges(path, m, spec.theta(m), "dt" in spec.config)  # every parameter present, each within its range
    # A missing scale silently became 1.0 (a −6 cm output); a non-positive dt breaks every per-sample model.
    needed = [k for k in ("u_scale", "y_scale") if k in m.config() and k not in spec.config]
    if needed:
        raise ParamsError(f"{path}: model.{' and model.'.join(needed)} missing (V per model unit, m per model unit); "
                          "a params file written by 'hyst fit' has them")
    for k in ("u_scale", "y_scale", "dt"):
        v = spec.config.get(k)
        if v is not None and not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
            raise ParamsError(f"{path}: model.{k} must be a positive number, got {v!r}")
    return spec


def _check_ranges(path: Path, m: Model, theta: np.ndarray, has_dt: bool = True) -> None:
    """Refuse a value outside the range its parameter is defined on (:attr:`Model.bounds`, where the fitters search
    and the checks hold): a hand-written ``delay.tau: -0.5`` ran as no delay, ``creep.tilt: 42`` without a word."""
    lo, hi = m.bounds
    for p, v, a, b in zip(m.params(), theta, lo, hi):
        if not a <= v <= b:
            unit = f" {p.unit}" if p.unit else ""
            hint = "" if has_dt else (" (the file gives no model.dt, so it is read at 1 kHz: add the period it was "
                                      "fitted at)")
            raise ParamsError(f"{path}: model.{p.name} = {v:g}{unit} lies outside its range [{a:g}, {b:g}]{unit}; "
                              f"correct it or refit{hint}")
