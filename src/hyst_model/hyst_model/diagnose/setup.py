"""What every stage of :func:`hyst_model.diagnose.diagnose.diagnose` reads and returns: the record and the fitted
base (:class:`Setup`), an effect tested against the data (:class:`Candidate`), a step of the error ladder
(:class:`Rung`)."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..model import Model
from .refit import rmse

__all__ = ["Candidate", "Rung", "Setup"]


@dataclass
class Candidate:
    """One effect tested against the data.

    Attributes
    ----------
    effect : str
    rmse : float
        Validation RMSE of base + effect (m).
    rmse_train : float
    improvement : float
        Baseline validation RMSE / this RMSE (> 1 is better).
    significant : bool
        Passes the margin and the paired test.
    score : float
        Residual-signature score in [0, 1].
    evidence : str
        Why, in words.
    t_stat : float
        Paired t statistic of the squared-error reduction on validation chunks.
    params : dict
        Fitted effect parameters (namespaced).
    """

    effect: str
    rmse: float
    rmse_train: float
    improvement: float
    significant: bool
    score: float
    evidence: str
    t_stat: float = 0.0
    params: dict = field(default_factory=dict)
    on_top_of: list = field(default_factory=list)
    note: str = ""
    #: The second-best screened configuration, ``(effect values, variant)``, when the screens held the base fixed:
    #: refitted jointly too (:func:`refit_all`). Not reported.
    runner_up: tuple | None = None
    #: ``(variant, values)`` of each configuration whose screen validated within ``min_factor`` of the best
    #: one's, or whose squared error exceeds the best one's by less than the best leaves above the noise floor
    #: (another effect still in the residual can tip the choice), the kept one included, with the base and effect
    #: values it reached: the record could not settle between them on the base, so the ladder refits its rungs
    #: in the others too (:mod:`.alike`). Not reported.
    alike: list = field(default_factory=list)
    #: Validation RMSE (m) of the final model refitted without this effect (the backward step's last round, on
    #: the final model: what this effect adds given the others); None where not tested (a one-effect answer, an
    #: effect not in it, a refit that failed). Ranks the final model's effects after the first
    #: (:func:`~.verdict.final_order`).
    rmse_without: float | None = None


@dataclass
class Rung:
    """One step of the error ladder."""

    model: str
    #: The rung's effects in the order its model applies them (innermost first: what ``hyst fit --effects``
    #: takes); the diagnosis's ranking is :func:`~.verdict.final_order`'s.
    effects: list
    rmse: float
    rmse_train: float


@dataclass
class Setup:
    """What every stage reads: the record, the hold-out, the configuration and the fitted base."""

    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    val: np.ndarray
    dt: float
    cfg: dict
    fixed: dict
    base: str
    base_model: Model
    names: list
    fit: Callable
    say: Callable
    noise: float
    th_base: np.ndarray
    e_base: np.ndarray
    min_factor: float
    t_min: float
    noise_margin: float
    full_rate_top: int
    max_rungs: int
    #: Threads for the candidates' fits (:func:`~.parallel.pmap`); the result does not depend on it.
    jobs: int = 1

    @property
    def train(self) -> np.ndarray:
        return ~self.val

    @property
    def base_val(self) -> float:
        return rmse(self.e_base[self.val])

    @property
    def at_floor(self) -> bool:
        return self.base_val <= self.noise_margin * self.noise
