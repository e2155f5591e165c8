"""``hyst demo`` end to end (lockstep, short schedule): exit 0, a readable bag, a summary per algorithm."""
import subprocess
import sys
from pathlib import Path

import pytest

from hyst_model.io.bag import read_joint_states

pytestmark = [pytest.mark.slow, pytest.mark.ros]
HYST = str(Path(sys.executable).parent / "hyst")


def test_demo_records_a_bag_and_prints_the_summary(tmp_path):
    # lockstep: the result does not depend on the machine's load, only the wall time does (generous deadline)
    proc = subprocess.run([HYST, "demo", "--lockstep", "--schedule", "dppc:1,pid:1", "--bags", str(tmp_path)],
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    rows = {ln.split()[0]: ln.split() for ln in proc.stdout.splitlines() if ln.startswith(("dppc ", "pid "))}
    assert set(rows) == {"dppc", "pid"}
    assert float(rows["dppc"][2]) < 0.01 < float(rows["pid"][2])  # RMSE in µm: DPPC at the noise floor
    # lockstep: each segment is 1 s of the stage's time, 2000 samples less the 0.25 s settling skip, whatever the
    # load (by the wall clock a loaded machine scored DPPC on 367-828 of them)
    assert all(abs(int(rows[a][1]) - 1500) <= 5 for a in ("dppc", "pid")), proc.stdout
    bags = list(tmp_path.glob("demo_*"))
    assert len(bags) == 1
    states = read_joint_states(bags[0], "/stage/state")
    cmds = read_joint_states(bags[0], "/stage/command")
    assert len(states.stamp_ns) > 1000 and len(cmds.stamp_ns) > 1000


def test_demo_on_the_gma_runs_its_stage_and_places_the_sine_on_its_stroke(tmp_path):
    """--profile gma: the GMA's embedded stage at ±5 V; the sine about 0 µm (on the PEA's 5–25 µm it would leave
    the GMA's ±20 µm stroke at its top)."""
    import numpy as np

    proc = subprocess.run([HYST, "demo", "--profile", "gma", "--lockstep", "--schedule", "dppc:1", "--bags",
                           str(tmp_path)], capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0 and "GMA stage" in proc.stdout, proc.stdout + proc.stderr
    rows = {ln.split()[0]: ln.split() for ln in proc.stdout.splitlines() if ln.startswith("dppc ")}
    assert float(rows["dppc"][2]) < 0.01
    bag = next(tmp_path.glob("demo_*"))
    y = np.asarray(read_joint_states(bag, "/stage/state").position)
    u = np.asarray(read_joint_states(bag, "/stage/command").effort)
    assert y.min() < -5e-6 and y.max() > 5e-6 and abs(0.5 * (y.min() + y.max())) < 2e-6
    assert u.min() < -1.0 and u.max() > 1.0 and u.min() >= -5.0 and u.max() <= 5.0


def test_demo_refuses_a_bad_schedule_with_one_line(tmp_path):
    proc = subprocess.run([HYST, "demo", "--schedule", "dppc:1,lqr:1", "--bags", str(tmp_path)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert "hyst demo: error:" in proc.stderr and "Traceback" not in proc.stderr
    assert not list(tmp_path.glob("demo_*"))


def test_warm_up_runs_each_algorithm_and_rejects_unknown_ones(monkeypatch):
    from hyst_control.errors import ControlError
    import hyst_bringup.loop as loop
    ran = []
    real = loop.run_closed_loop

    def spy(ctrl, *a, **k):  # the warm-up must really run each law's loop (that is what compiles it)
        res = real(ctrl, *a, **k)
        ran.append((type(ctrl).__name__, len(res.y)))
        return res
    monkeypatch.setattr(loop, "run_closed_loop", spy)
    loop.warm_up(["dppc", "dmrac", "pid", "open_loop"], 2000.0)
    assert len(ran) == 4 and len({name for name, _ in ran}) == 4, ran
    assert all(n >= 10 for _, n in ran), ran  # 0.01 s at 2 kHz: samples were stepped, not skipped
    with pytest.raises(ControlError):
        loop.warm_up(["wobble"], 2000.0)


def test_demo_refuses_a_bad_rt_priority_with_one_line(tmp_path):
    bags = tmp_path / "new" / "bags"
    proc = subprocess.run([HYST, "demo", "--rt-priority", "120", "--bags", str(bags)], capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 2 and proc.stderr.strip().count("\n") == 0 and "rt-priority" in proc.stderr
    assert not (tmp_path / "new").exists()  # refused before anything was made


@pytest.mark.parametrize("where", ["a_file", "a_file/below"])
def test_demo_refuses_a_bags_path_it_cannot_use_with_one_line(tmp_path, where):
    (tmp_path / "a_file").write_text("mine\n")
    proc = subprocess.run([HYST, "demo", "--schedule", "dppc:0.2", "--bags", str(tmp_path / where)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr and "--bags" in proc.stderr, proc.stderr
    assert (tmp_path / "a_file").read_text() == "mine\n"


def test_the_summary_says_when_the_machine_missed_real_time_periods():
    from hyst_bringup.demo import timing_note

    assert timing_note(11900, 100, 2000.0) is None  # < 5 % missed
    assert timing_note(0, 0, 2000.0) is None
    note = timing_note(5000, 7000, 2000.0)
    assert note is not None and "58 %" in note and "2000 Hz" in note and "--lockstep" in note
