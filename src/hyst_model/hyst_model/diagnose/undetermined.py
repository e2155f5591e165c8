"""Effects the record cannot tell apart: from the base model, or from the effect named.

A diagnosis answers from validation, so an effect the base model (refitted with it) takes on the record is not
named — and the user reads "none". On a few sines a transport delay is a phase the MBW's memory terms also
make, on slow triangles a warm-up drift is a slow change the loop's offset and creep follow: the effect fitted
with the base changes the model's output by tens of times the sensor noise, yet the base refitted alone
validates as well. The record does not determine it, and on another input (a fresh record of the same stage) the
base alone may be far worse (generated GMA stages with a delay on sines: 4–14× the error the true delay leaves).
Two effects can also validate alike against each other (a mode seen below its resonance and a delay).

The diagnosis says so, with the numbers, and what to record to tell them apart. It changes no answer.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import cast

import numpy as np

from ..effects.base import ComposedModel
from ..effects.signals import fmt_len
from .refit import paired_t, rmse
from .setup import Setup
from .stages import validate_alike

__all__ = ["CONTRIBUTION", "Undetermined", "undetermined", "sentence", "excite_command"]

#: An effect whose part of the fitted model's output (the model minus its base, same parameters) is at least this
#: many times the noise floor RMS would be seen by a record that could tell; validating alike with the base, it is
#: undetermined. On generated records without an effect the largest part any fitted effect took was 1.6× (32
#: records of seed 27 and others read for this: 0–1.6×); a delay the base absorbed on sines took 31–39×.
CONTRIBUTION = 3.0


@dataclass
class Undetermined:
    """One effect the record does not determine (``hyst diagnose --json``: ``undetermined``)."""

    effect: str
    #: "the base" (the effect validates as the base alone does) or the effect named that it validates alike with.
    against: str
    rmse: float
    #: RMS of the effect's part of its fitted model's output, in noise-floor units (None: not computed).
    contribution: float | None
    params: dict

    def to_json(self) -> dict:
        return asdict(self)


def _part(s: Setup, m, th: np.ndarray) -> float | None:
    """RMS (noise-floor units) of what the effect adds to the output of its base+effect model ``(m, θ)``."""
    if any(getattr(ef, "kind", "") == "base" for ef in getattr(m, "effects", ())):
        return None  # an effect that replaces the base recursion: no base to compare with (as rebase skips it)
    th_b = cast(ComposedModel, m).split(th)[0]
    with np.errstate(all="ignore"):
        diff = m.simulate(th, s.t, s.u) - s.base_model.simulate(th_b, s.t, s.u)
    return float(np.sqrt(np.mean(diff ** 2)) / s.noise) if np.all(np.isfinite(diff)) and s.noise > 0 else None


def undetermined(s: Setup, full: dict, cands: dict, named: list) -> list[Undetermined]:
    """The effects of the first rung (each refitted jointly with the base, ``full``) the record cannot tell apart.

    With nothing named: each effect validating alike with the base (:func:`~.stages.validate_alike`) whose part
    of its model's output is at least :data:`CONTRIBUTION` × the noise. With an effect named: each other
    significant effect validating alike with the named one's own refit on the base.
    """
    out: list[Undetermined] = []
    val = s.val
    if not named:
        for nm, (m, th, e) in full.items():
            r = rmse(e[val])
            if not validate_alike(s, s.base_val, r, paired_t(s.e_base[val], e[val])):
                continue
            part = _part(s, m, th)
            if part is not None and part >= CONTRIBUTION:
                out.append(Undetermined(nm, "the base", r, part, dict(cands[nm].params) if nm in cands else {}))
        return sorted(out, key=lambda x: -(x.contribution or 0.0))
    first = named[0]
    if first not in full:
        return out
    e_n = full[first][2]
    r_n = rmse(e_n[val])
    for nm, (m, th, e) in full.items():
        if nm in named or nm not in cands or not cands[nm].significant:
            continue
        r = rmse(e[val])
        best, other, e_best, e_other = (r_n, r, e_n, e) if r_n <= r else (r, r_n, e, e_n)
        if validate_alike(s, other, best, paired_t(e_other[val], e_best[val])):
            out.append(Undetermined(nm, first, r, None, dict(cands[nm].params)))
    return sorted(out, key=lambda x: x.rmse)


def _values(params: dict, effect: str, at_most: int = 3) -> str:
    items = [(k.split(".", 1)[1], v) for k, v in params.items() if k.startswith(effect + ".")]
    shown = ", ".join(f"{k} {v:.3g}" for k, v in items[:at_most])
    return shown + (", ..." if len(items) > at_most else "")


def sentence(items: list[Undetermined], noise: float, dt: float | None = None,
             u_range: tuple[float, float] | None = None) -> str:
    """The note in words ('' for none): what the record does not determine, and what to record to tell — the
    ``hyst excite`` command for a record of this rate and input range (:func:`excite_command`)."""
    if not items:
        return ""
    alone = [x for x in items if x.against == "the base"]
    alike = [x for x in items if x.against != "the base"]
    parts = []
    if alone:
        what = "; ".join(f"{x.effect} ({_values(x.params, x.effect)}: {x.contribution:.3g}× the noise)"
                         for x in alone)
        parts.append(f"but this record does not determine {what} (fitted values in SI units; the noise multiple "
                     "is how much the effect changes the model's output): with it the refitted base validates as the "
                     "base alone does — the base takes it on this input — so the record can neither show nor "
                     "exclude it")
    if alike:
        what = "; ".join(f"{x.effect} ({_values(x.params, x.effect)}) validates at {fmt_len(x.rmse)} "
                         f"({x.rmse / noise:.2f}× the noise floor)" for x in alike)
        parts.append(f"this record does not tell {alike[0].against} from: {what}")
    return ("; ".join(parts) + "; record steps with holds, band-limited noise or a sweep over the range to tell "
            f"them apart ({excite_command(dt, u_range)} writes one and prints the hyst_excite_node command that "
            "plays it)")


def excite_command(dt: float | None, u_range: tuple[float, float] | None) -> str:
    """The ``hyst excite`` command for a record like this one: its rate and its input's reach (a stage is excited
    where it was identified). Inside an amplifier profile's range (PEA 0–150 V, GMA ±5 V) it names that profile —
    with the record's lowest level as ``--v-min`` where a PEA record stays above 1.5 V (its rest is then there, not
    at 0 V where the stage was never driven); a record beyond both (another stage, e.g. ±10 V) gets
    ``--profile custom`` with the record's own range (never a profile's default range, which could drive that
    stage beyond what it was driven). Without a range, the generic command."""
    cmd = "hyst excite --parts steps,noise,sweep"
    if dt is not None and np.isfinite(dt) and dt >= 1e-5:
        cmd += f" --rate {1.0 / dt:.6g}"
    if u_range is not None:
        lo, hi = (float(v) for v in u_range)
        reach = 0.9999 * max(abs(lo), abs(hi))  # inward by 0.01 %: a printed figure rounded up would leave it
        if 0.0 <= lo < hi <= 150.0:  # from the record's lowest level: a 20-120 V stage is not driven to 0 V
            low = f" --v-min {lo + 1e-4 * (hi - lo):.6g}" if lo > 0.01 * 150.0 else ""
            cmd += f" --profile pea{low} --v-max {0.9999 * hi:.6g}"
        elif -5.0 <= lo < 0.0 < hi <= 5.0:
            cmd += f" --profile gma --v-min {-reach:.6g} --v-max {reach:.6g}"
        elif np.isfinite(lo) and np.isfinite(hi) and lo < hi:
            pad = 1e-4 * (hi - lo)  # inward, as above
            cmd += f" --profile custom --v-min {lo + pad:.6g} --v-max {hi - pad:.6g}"
    return cmd + " --out excite.csv"
