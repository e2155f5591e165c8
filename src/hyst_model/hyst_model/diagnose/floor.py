"""The sensor noise floor of a diagnosis: what it is made of, and the sentence that says so.

Four sources, one floor (m RMS):

* the white part, from second differences (:func:`~hyst_model.effects.signals.record_floor`) — always; for a
  reading quantised in steps not fine against its noise, the quantisation error with the noise, read by local
  fits (:mod:`~hyst_model.effects.quantised`: second differences misread it), and the step is said;
* noise that is not white, read where the input is held still (:mod:`.colour`) — where it exceeds the white part
  by :data:`~.colour.MARGIN`; read on the record without the lines below, which it would otherwise count as
  "not white";
* lines the input does not drive that were found only in the final model's residual (:mod:`.lines`; those found
  in the base's residual are taken out of the record before fitting and are not part of the floor);
* the sensor noise the user gives (``--sensor-noise``) — where it is more than the record shows.

The floor is the larger of the given value and ``hypot(held or white, lines…)``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..effects.signals import fmt_len
from .colour import HeldNoise, hold_noise, not_white
from .lines import Line, floor_with_lines, said, without_lines

__all__ = ["Floor", "read_floor"]


@dataclass(frozen=True)
class Floor:
    """What a diagnosis's noise floor is made of (SI: m)."""

    white: float                       # second differences (local fits on a coarse lattice)
    held: HeldNoise | None = None      # read in the holds, where above MARGIN × white
    lines: tuple[Line, ...] = ()       # found in the final residual, counted here
    given: float | None = None         # the user's sensor noise, whatever its size
    step: float = 0.0                  # the reading's quantisation step where not fine against its noise, else 0

    @property
    def measured(self) -> float:
        """What the record shows: the holds' reading (or the white part) with the lines."""
        return floor_with_lines(self.held.rms if self.held is not None else self.white, list(self.lines))

    @property
    def given_used(self) -> bool:
        return self.given is not None and self.given > self.measured

    @property
    def value(self) -> float:
        """The floor (m RMS)."""
        return float(self.given) if self.given_used else self.measured   # type: ignore[arg-type]

    def words(self) -> str:
        """The sentence a diagnosis adds about its floor ("" for white noise alone)."""
        # what the record's differences or local fits show: its white part, or its quantisation error with it
        shown = (f"the quantisation error with the white noise this record shows ({fmt_len(self.white)}; it reads "
                 f"in steps of {fmt_len(self.step)})" if self.step > 0.0
                 else f"the white part this record shows ({fmt_len(self.white)})")
        if self.given_used:
            out = (f"the noise floor {fmt_len(self.value)} is the sensor noise given, "
                   f"{self.value / self.white:.2g}× {shown}")
            return out + (f"; the final model's residual also holds {said(list(self.lines))} that the input does "
                          "not drive" if self.lines else "")
        parts = []
        if self.step > 0.0 and self.held is None:
            parts.append(f"the quantisation error of a sensor reading in steps of {fmt_len(self.step)}, with its "
                         "noise" + (f" ({fmt_len(self.white)})" if self.lines else ""))
        if self.held is not None:
            parts.append(f"noise read in the record's {self.held.holds} holds (the input still), "
                         f"{fmt_len(self.held.rms)}, {self.held.rms / self.white:.2g}× "
                         + ("the rest of the record's quantisation error with its white noise"
                            f" ({fmt_len(self.white)}, in steps of {fmt_len(self.step)})" if self.step > 0.0
                            else f"its white part ({fmt_len(self.white)})")
                         + " — not white: electronics slower than the sampling, or the bench vibrating?")
        elif self.lines and self.step <= 0.0:
            parts.append(f"white sensor noise ({fmt_len(self.white)})")
        if self.lines:
            parts.append(f"{said(list(self.lines))} that the input does not drive (mains pickup or an amplifier's "
                         "ripple?)")
        if not parts:
            out = ""
        else:
            out = (f"the noise floor {fmt_len(self.value)} holds " + " and ".join(parts)
                   + ": no model of the stage removes " + ("them" if len(parts) > 1 or len(self.lines) > 1 else "it")
                   + (" — filter or shield the sensor to go below" if self.lines else ""))
        if self.given is not None:
            more = f"the record shows more noise ({fmt_len(self.value)}) than the sensor noise given " \
                   f"({fmt_len(self.given)})"
            out = f"{out} ({more})" if out else more
        return out


def read_floor(t: np.ndarray, u: np.ndarray, y: np.ndarray, white: float, given: float | None = None,
               lines: list[Line] | None = None, step: float = 0.0) -> tuple[Floor, HeldNoise | None]:
    """The floor of record ``y`` whose white part is ``white``, with ``lines`` (the final residual's), the
    user's ``given`` noise and the reading's coarse quantisation ``step`` (0: none); and the holds' reading
    whatever its size (None: the record has too few holds)."""
    lines = list(lines or [])
    reading = hold_noise(t, u, without_lines(t, y, lines))
    held = reading if not_white(reading, white, y) else None
    return Floor(white, held, tuple(lines), given, step), reading
