"""Root pytest configuration shared by every test directory."""
from __future__ import annotations

import os

import pytest


def pytest_addoption(parser):
    parser.addoption("--device", action="store", default=None,
                     help="serial port of a real amplifier/sensor; enables hardware tests")


def pytest_configure(config):
    # Keep every test's ROS traffic on this host; a domain id per run unless CI chose one.
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_DOMAIN_ID", str(10 + os.getpid() % 90))


@pytest.fixture
def ctx():
    """An isolated rclpy context for one test (nodes in it do not share the default context's state)."""
    rclpy = pytest.importorskip("rclpy")
    c = rclpy.Context()
    rclpy.init(context=c)
    yield c
    rclpy.try_shutdown(context=c)


@pytest.fixture(autouse=True)
def _effect_registry_restored():
    """Effects a test registers (a user effect module, a test effect) leave with the test: a later in-process
    ``hyst diagnose`` would otherwise screen them as candidates (a leaked failing effect came out as a candidate
    with no RMSE)."""
    import sys

    yield
    compose = sys.modules.get("hyst_model.effects.compose")
    if compose is not None:
        builtin = {n: c for n, c in compose.EFFECTS.items() if c.__module__.startswith("hyst_model.effects.")}
        compose.EFFECTS.clear()
        compose.EFFECTS.update(builtin)


@pytest.fixture
def ten_volt_stage(tmp_path) -> str:
    """A params file of a ±10 V stage (the GMA loop shape on 1 V per model unit), identified at 1 kHz: another
    stage for ``profile custom`` (sim, driver, controller)."""
    from hyst_model.core import stage_model

    m = stage_model("gma").replace(u_scale=1.0)
    body = "".join(f"      {k}: {v!r}\n" for k, v in m.to_dict().items())
    p = tmp_path / "stage10.yaml"
    p.write_text("/**:\n  ros__parameters:\n    model:\n      base: mbw\n" + body +
                 f"      u_scale: {m.u_scale!r}\n      y_scale: {m.y_scale!r}\n      dt: 0.001\n")
    return str(p)
