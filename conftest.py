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
