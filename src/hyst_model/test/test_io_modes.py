"""Outputs are written with the user's umask (mkstemp alone gave 0600), also when --force replaces a file."""
from __future__ import annotations

import os
import stat

import numpy as np
import pytest

from hyst_model.io import write_csv
from hyst_model.io.modes import mkstemp_user, user_umask


@pytest.fixture
def umask():
    def set_(m):
        old = os.umask(m)
        olds.append(old)
    olds: list[int] = []
    yield set_
    for o in reversed(olds):
        os.umask(o)


@pytest.mark.parametrize("mask,mode", [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_mkstemp_user_follows_the_umask(tmp_path, umask, mask, mode):
    umask(mask)
    assert user_umask() == mask
    fd, p = mkstemp_user(dir=tmp_path)
    os.close(fd)
    assert stat.S_IMODE(os.stat(p).st_mode) == mode


def test_written_and_replaced_files_get_the_user_mode(tmp_path, umask):
    umask(0o022)
    p = tmp_path / "y.csv"
    write_csv(p, {"t": np.arange(3.0), "y": np.zeros(3)})
    assert stat.S_IMODE(os.stat(p).st_mode) == 0o644
    os.chmod(p, 0o600)
    write_csv(p, {"t": np.arange(3.0), "y": np.ones(3)}, force=True)
    assert stat.S_IMODE(os.stat(p).st_mode) == 0o644
