"""Files that configure the simulated stage: hidden scenarios and params files (IO layer, no rclpy).

Hidden scenario
---------------
A YAML file naming the effects a test wants present without telling the code under test::

    hyst_sim_scenario: 1          # format marker (required)
    effects:                      # effect name -> strength, or a mapping of its settings
      creep: {strength: 0.012, tau_min: 0.01, tau_max: 300.0, per_decade: 4}
      delay: 3
    mbw_factors: {zeta1: 1.2}     # optional: the true stage differs from the params file (model mismatch)
    seed: 7                       # optional: noise/drift seed

Effect names and settings are those of :mod:`hyst_sim.truth_effects`. The effects a scenario names replace the
base configuration's (the sim node's ``effects.*`` parameters keep their visible values). Nothing here prints a
scenario's contents: :class:`Scenario` has an opaque ``repr``, and error messages name the file and the
structural problem (an unknown key, a bad value type) but not hidden values.

Params file
-----------
:func:`load_params_file` reads the model of a params file through :func:`hyst_model.io.params_file.read_params`
and returns its MBW part with SI scaling.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from pathlib import Path
from typing import NamedTuple

from hyst_model.core import PARAM_NAMES, MBWParams
from hyst_model.io.params_file import NUMBER

from .errors import ConfigError, ScenarioError
from .truth_effects import EFFECT_NAMES, Effects

__all__ = ["Scenario", "load_scenario", "scenario_dir", "ParamsFileModel", "load_params_file"]

_FORMAT_KEY = "hyst_sim_scenario"


def scenario_dir() -> Path:
    """Directory of the scenario files shipped with hyst_sim (``hidden_*.yaml``)."""
    return Path(__file__).resolve().parent / "data" / "scenarios"


@dataclass(frozen=True, repr=False)
class Scenario:
    """Hidden effects (and optional model mismatch) to apply on top of a plant configuration.

    The ``repr`` never shows the contents, so a stray log line cannot give the scenario away.
    """

    effects: tuple = ()          # ((name, effect object), ...)
    mbw_factors: tuple = ()      # ((param name, factor), ...)
    seed: int | None = None
    source: str = ""

    def __repr__(self) -> str:
        return "Scenario(<hidden>)"

    __str__ = __repr__

    def apply(self, config):
        """Return ``config`` (a :class:`hyst_sim.plant.PlantConfig`) with this scenario's effects and mismatch."""
        kw = {}
        if self.effects:
            kw["effects"] = config.effects.with_effects(**dict(self.effects))
        if self.mbw_factors:
            kw["mbw"] = config.mbw.replace(**{n: getattr(config.mbw, n) * f for n, f in self.mbw_factors})
        if self.seed is not None:
            kw["seed"] = self.seed
        try:
            return config.replace(**kw) if kw else config
        except ConfigError:
            raise ScenarioError(f"{self.source}: the scenario does not fit this plant (out-of-range setting)") \
                from None


def _typed(p: Path, cls, settings: dict) -> dict:
    """Each setting as its field's type: a finite number for a number (``4e-9`` as YAML 1.1 leaves it, a whole
    ``3.0`` for an integer), true/false for a flag. ``sine: .inf`` loaded and put the reading at −1.8e10 m,
    ``two_sided: 'no'`` meant two-sided and ``dynamics: true`` a 1 Hz resonance."""
    types = {f.name: str(f.type) for f in fields(cls)}
    out = {}
    for k, v in settings.items():
        kind = types.get(k, "float")
        if isinstance(v, str) and NUMBER.fullmatch(v.strip()):  # YAML 1.1 leaves 4e-9 a string
            v = float(v)
        if "bool" in kind:
            if v is not None and not isinstance(v, bool):
                raise ScenarioError(f"{p}: an effect's flag is not true or false")  # names no setting: hidden
        elif isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ScenarioError(f"{p}: an effect setting is not a finite number")
        elif "int" in kind and "float" not in kind:
            if v != int(v):
                raise ScenarioError(f"{p}: an effect's count is not a whole number")
            v = int(v)
        out[k] = v
    return out


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario file; see the module docstring for the format.

    Raises
    ------
    ScenarioError
        Missing/unreadable file, wrong format, unknown effect or setting, value out of range. The message never
        contains the file's values.
    """
    import yaml  # late: only file loading needs it

    p = Path(path).expanduser()
    if not p.is_file():
        raise ScenarioError(f"{p}: no such scenario file")
    try:
        doc = yaml.safe_load(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as err:
        raise ScenarioError(f"{p}: cannot read scenario file ({type(err).__name__})") from None
    if not isinstance(doc, dict) or doc.get(_FORMAT_KEY) != 1:
        raise ScenarioError(f"{p}: not a hyst_sim scenario (expected '{_FORMAT_KEY}: 1' at the top)")
    unknown = set(doc) - {_FORMAT_KEY, "effects", "mbw_factors", "seed", "description"}
    if unknown:
        raise ScenarioError(f"{p}: unknown top-level key(s) {', '.join(sorted(map(str, unknown)))}")
    effects = []
    raw = doc.get("effects") or {}
    if not isinstance(raw, dict):
        raise ScenarioError(f"{p}: 'effects' must be a mapping of effect name to settings")
    for name, val in raw.items():
        if name not in EFFECT_NAMES:
            raise ScenarioError(f"{p}: unknown effect name (valid: {', '.join(EFFECT_NAMES)})")
        cls = Effects.effect_class(name)
        settings = val if isinstance(val, dict) else {"strength": val}
        allowed = {f.name for f in fields(cls)}
        if set(settings) - allowed:
            raise ScenarioError(f"{p}: an effect has an unknown setting (allowed per effect: see truth_effects)")
        settings = _typed(p, cls, settings)
        try:
            eff = cls(**settings)
            eff.validate()
        except (TypeError, ConfigError):
            raise ScenarioError(f"{p}: an effect setting is invalid or out of range") from None
        effects.append((name, eff))
    factors = doc.get("mbw_factors") or {}
    if not isinstance(factors, dict) or set(factors) - set(PARAM_NAMES) or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0
            for v in factors.values()):
        raise ScenarioError(f"{p}: 'mbw_factors' must map MBW parameter names to positive finite numbers")
    seed = doc.get("seed")
    if seed is not None and not (isinstance(seed, int) and not isinstance(seed, bool) and seed >= 0):
        raise ScenarioError(f"{p}: 'seed' must be a non-negative integer")
    return Scenario(tuple(effects), tuple((str(k), float(v)) for k, v in factors.items()), seed, str(p))


class ParamsFileModel(NamedTuple):
    """The part of a params file the plant uses."""

    mbw: MBWParams
    dt: float | None
    ignored_effects: tuple[str, ...]


def load_params_file(path: str | Path) -> ParamsFileModel:
    """MBW parameters (with ``u_scale``, ``y_scale``, ``offset``) and ``dt`` of a params file.

    Fitted effects in the file (``model.effects``) are not part of the plant's truth; they are returned in
    ``ignored_effects`` so the caller can say so (the plant's effects are its own ``effects.*`` settings).

    Raises
    ------
    ScenarioError
        Unreadable file, or a base model other than ``mbw``/``bw``.
    """
    from hyst_model.errors import HystError
    from hyst_model.io.params_file import read_params

    try:
        spec = read_params(path)
    except HystError as err:
        raise ScenarioError(str(err)) from err
    if spec.base not in ("mbw", "bw"):
        raise ScenarioError(f"{path}: the simulated stage needs an 'mbw' or 'bw' model, not {spec.base!r}")
    vals = {k: float(v) for k, v in spec.values.items()}
    missing = [n for n in PARAM_NAMES if n not in vals and not (spec.base == "bw" and n in ("zeta2", "psi2",
                                                                                             "alpha2"))]
    if missing:
        raise ScenarioError(f"{path}: model lacks {', '.join(missing)}")
    d = {n: vals.get(n, 0.0) for n in PARAM_NAMES}
    cfg = spec.config
    try:
        mbw = MBWParams(**d, u_scale=float(cfg.get("u_scale", 1.0)), y_scale=float(cfg.get("y_scale", 1.0)),
                        offset=float(vals.get("offset", 0.0)))
        dt = float(cfg["dt"]) if cfg.get("dt") is not None else None
    except (TypeError, ValueError) as err:
        raise ScenarioError(f"{path}: invalid model configuration ({err})") from None
    if dt is not None and not (math.isfinite(dt) and dt > 0):
        raise ScenarioError(f"{path}: model.dt must be a positive number of seconds")
    return ParamsFileModel(mbw, dt, tuple(spec.effects))

