"""How diagnose chooses between candidates that validate alike (ladder.prefer_simpler)."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from hyst_model.diagnose.ladder import SIGNATURE_MARGIN, n_params, prefer_simpler
from hyst_model.spec import build_model

CFG = {"dt": 5e-4, "u_scale": 15.0, "y_scale": 5e-6}


def _setup():
    n = 4000
    val = np.zeros(n, dtype=bool)
    val[::4] = True
    return SimpleNamespace(base_model=build_model("mbw", [], CFG), cfg=dict(CFG), val=val, train=~val, t_min=3.0,
                           min_factor=1.1), n


def test_the_best_by_validation_wins_when_it_is_significantly_better():
    s, n = _setup()
    rng = np.random.default_rng(0)
    e_good, e_bad = rng.normal(0, 1e-9, n), rng.normal(0, 3e-9, n)
    i, why = prefer_simpler(s, [("creep", 3e-9, e_bad, 0.9), ("dynamics", 1e-9, e_good, 0.0)])
    assert i == 1 and why == ""


def test_alike_candidates_go_to_the_fewer_parameters_and_a_disagreeing_signature_is_said():
    s, n = _setup()
    rng = np.random.default_rng(1)
    e = rng.normal(0, 1e-9, n)
    e2 = e + rng.normal(0, 1e-12, n)  # the same error to within a thousandth: they validate alike
    assert n_params(s, "delay") < n_params(s, "creep") < n_params(s, "dynamics")
    # parsimony, whatever the (insignificant) RMSE order
    i, why = prefer_simpler(s, [("dynamics", 0.999e-9, e, 0.30), ("delay", 1.0e-9, e2, 0.20)])
    assert i == 1 and "parameter" in why and "dynamics" in why and "disagree" not in why
    # a clearly stronger residual signature of the richer effect does not overrule the record; it is reported
    i, why = prefer_simpler(s, [("dynamics", 0.999e-9, e, 0.20 + SIGNATURE_MARGIN + 0.3),
                                ("delay", 1.0e-9, e2, 0.20)])
    assert i == 1 and "signatures disagree" in why
    i, why = prefer_simpler(s, [("delay", 0.999e-9, e2, 0.1), ("dynamics", 1.0e-9, e, 0.9)])
    assert i == 0 and why == ""
    # three alike: the fewest parameters among all of them
    i, _ = prefer_simpler(s, [("dynamics", 0.998e-9, e, 0.5), ("creep", 0.999e-9, e2, 0.5),
                              ("delay", 1.0e-9, e2, 0.5)])
    assert i == 2


def test_alike_candidates_the_training_part_tells_apart_are_not_taken_for_parsimony():
    s, n = _setup()
    rng = np.random.default_rng(4)
    noise = rng.normal(0, 1e-9, n)
    miss = np.where(s.val, 0.0, 6e-9 * np.sin(np.arange(n) / 5.0))  # ringing only the training samples show
    e_delay = noise + miss                            # the simpler one leaves it
    e_mode = noise + rng.normal(0, 1e-12, n)          # the richer one explains it; both validate alike
    opts = [("dynamics", 1.0e-9, e_mode, 0.8), ("delay", 0.999e-9, e_delay, 0.1)]
    i, why = prefer_simpler(s, opts)
    assert i == 0 and "training part" in why and "validation blocks do not reach" in why
    i, why = prefer_simpler(s, opts[::-1])  # whatever the order
    assert i == 1 and "training part" in why
    # where the training part sees no more than validation, parsimony decides as before
    i, why = prefer_simpler(s, [("dynamics", 0.999e-9, e_mode, 0.8), ("delay", 1.0e-9, noise.copy(), 0.1)])
    assert i == 1 and "fewer parameters" in why
    # a gain on training below min_factor does not overrule parsimony
    i, _ = prefer_simpler(s, [("dynamics", 0.999e-9, e_mode, 0.8), ("delay", 1.0e-9, noise + 0.1 * miss, 0.1)])
    assert i == 1


def _blind_setup():
    n = 8000
    val = np.zeros(n, dtype=bool)
    val[::4] = True
    return SimpleNamespace(val=val, train=~val, noise=1e-9, min_factor=1.1, t_min=3.0, noise_margin=1.1), n, val


def test_a_rung_validation_cannot_judge_takes_the_refit_training_needs():
    from hyst_model.diagnose.ladder import training_only
    s, n, val = _blind_setup()
    rng = np.random.default_rng(2)
    noise = rng.normal(0, 1e-9, n)
    miss = np.where(val, 0.0, 8e-9 * np.sin(np.arange(n) / 7.0))  # an error only the training samples show
    cur = noise + miss
    cur_val = float(np.sqrt(np.mean(cur[val] ** 2)))
    fixed = noise + rng.normal(0, 1e-11, n)                # a refit that removes it
    half = noise + 0.5 * miss                              # one that removes half of it
    trial = [(cur_val * 0.999, "delay", None, None, half), (cur_val, "dynamics", None, None, fixed)]
    ok, pick, why = training_only(s, trial, cur, cur_val)
    assert [x[1] for x in ok] == ["delay", "dynamics"] and ok[pick][1] == "dynamics"
    assert "training part's evidence" in why and "validation does not rise" in why
    # at the floor validation cannot tell them apart: a refit a little worse there but within the noise margin
    # of the floor is taken; one beyond it is not
    assert cur_val < s.noise_margin * s.noise
    ok, _, _ = training_only(s, [(cur_val * 1.01, "dynamics", None, None, fixed)], cur, cur_val)
    assert [x[1] for x in ok] == ["dynamics"]
    ok, pick, _ = training_only(s, [(1.01 * s.noise_margin * s.noise, "dynamics", None, None, fixed)], cur, cur_val)
    assert ok == [] and pick == -1
    # above the floor, a refit worse on validation at all is not taken
    s_low = SimpleNamespace(**{**vars(s), "noise": 0.5e-9})
    ok, pick, _ = training_only(s_low, [(cur_val * 1.01, "dynamics", None, None, fixed)], cur, cur_val)
    assert ok == [] and pick == -1
    # nor anything when the rung trains as well as it validates: the hold-out sees what training sees
    ok, _, _ = training_only(s, trial, noise, float(np.sqrt(np.mean(noise[val] ** 2))))
    assert ok == []
    # nor a refit that helps training too little (below min_factor)
    slight = noise + 0.95 * miss
    ok, _, _ = training_only(s, [(cur_val, "creep", None, None, slight)], cur, cur_val)
    assert ok == []


def test_a_function_of_time_is_taken_on_training_only_before_the_first_validation_block():
    from hyst_model.diagnose.ladder import training_only
    n = 8000
    val = np.zeros(n, dtype=bool)
    val[2000::4] = True  # the blocks begin at sample 2000
    s = SimpleNamespace(val=val, train=~val, noise=1e-9, min_factor=1.1, t_min=3.0, noise_margin=1.1)
    rng = np.random.default_rng(3)
    noise = rng.normal(0, 1e-9, n)
    k = np.arange(n)
    late = np.where(val | (k < 2000), 0.0, 6e-9 * np.sin(k / 50.0))  # training-only error between the blocks
    early = np.where(k < 2000, 6e-9 * np.exp(-k / 400.0), 0.0)  # a warm-up over before the first block
    for miss, taken in ((late, False), (early, True)):
        cur = noise + miss
        cur_val = float(np.sqrt(np.mean(cur[val] ** 2)))
        trial = [(cur_val, "drift", None, None, noise.copy())]
        ok, _, _ = training_only(s, trial, cur, cur_val)
        assert bool(ok) is taken
        # an input-dependent effect is judged on the whole training part
        ok, _, _ = training_only(s, [(cur_val, "dynamics", None, None, noise.copy())], cur, cur_val)
        assert ok


def test_a_rung_refits_only_simpler_configurations_that_screened_alike():
    from hyst_model.diagnose.alike import simpler_alike as _simpler_alike
    s, _ = _setup()
    two, one = {"dynamics.modes": 2.0}, {"dynamics.modes": 1.0}
    best = (1.00e-9, "dynamics", {"dynamics.fn": 500.0}, None, two)
    alike = (1.05e-9, "dynamics", {"dynamics.fn": 480.0}, None, one)
    assert _simpler_alike(s, [best, alike], best) == [({"dynamics.fn": 480.0}, one)]
    far = (1.2e-9, "dynamics", {}, None, one)  # screened worse by more than min_factor: not refitted
    assert _simpler_alike(s, [best, far], best) == []
    # a richer configuration that screened alike is not (a screen cannot judge it: _rung_variants)
    best1 = (1.00e-9, "dynamics", {}, None, one)
    assert _simpler_alike(s, [best1, (1.01e-9, "dynamics", {}, None, two)], best1) == []


def test_the_final_models_effects_after_the_first_rank_by_what_each_adds():
    from hyst_model.diagnose.setup import Candidate
    from hyst_model.diagnose.verdict import final_order

    def cand(nm, without):
        return Candidate(nm, 1e-9, 1e-9, 1.0, True, 0.0, "", rmse_without=without)

    cands = {"creep": cand("creep", 17.5e-9), "delay": cand("delay", 2.62e-9), "dynamics": cand("dynamics", 4.37e-9)}
    assert final_order(["creep", "delay", "dynamics"], cands) == ["creep", "dynamics", "delay"]
    # the first stays first even where dropping another costs more: it explains most of the error on its own
    cands["creep"].rmse_without = 1e-9
    assert final_order(["creep", "delay", "dynamics"], cands)[0] == "creep"
    # untested (the backward step did not run on every one of them): the ladder's order stands
    cands["delay"].rmse_without = None
    assert final_order(["creep", "delay", "dynamics"], cands) == ["creep", "delay", "dynamics"]
    assert final_order(["creep", "delay"], cands) == ["creep", "delay"]
