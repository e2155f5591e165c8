"""The diagnosis's progress display: steps counted against an estimate that never reads below the count."""
from __future__ import annotations

from hyst_model.diagnose.refit import _Progress


def test_the_step_count_never_passes_the_total(capsys):
    say = _Progress(True, 2)
    for k in range(4):
        say(f"step {k}")
        say("a note, not a step", step=False)
    lines = capsys.readouterr().err.splitlines()
    heads = [ln.split("]")[0].split()[1] for ln in lines]
    assert heads == ["1/2", "1/2", "2/2", "2/2", "3/3", "3/3", "4/4", "4/4"]
