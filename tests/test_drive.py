"""Tests of racing_lib.model.drive: one length convention, checked inputs, files that read back."""

from __future__ import annotations

import numpy as np
import pytest

from racing_lib.errors import ModelError
from racing_lib.experiments.lap import LapLog
from racing_lib.model import Drive


def _columns(n: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(0)
    names = ("t", "x", "y", "psi", "vx", "vy", "r", "steer", "pedal")
    return {k: rng.standard_normal(n) for k in names}


def test_every_column_has_one_entry_per_sample():
    cols = _columns(5)
    cols["steer"] = cols["steer"][:-1]  # the old "N + 1 observations, N commands"
    with pytest.raises(ModelError, match="steer has 4 samples, t has 5"):
        Drive(**cols)
    with pytest.raises(ModelError, match="theta has 3 samples"):
        Drive(**_columns(5), theta=np.zeros(3))


def test_a_drive_reads_back_from_its_file(tmp_path):
    drive = Drive(**_columns(7), theta=np.linspace(0.0, 0.1, 7), name="circle", kind="circles")
    drive.save(tmp_path / "drive.npz")
    back = Drive.load(tmp_path / "drive.npz")
    assert (back.name, back.kind) == ("circle", "circles")
    for k in ("t", "vx", "steer", "theta"):
        np.testing.assert_array_equal(getattr(back, k), getattr(drive, k))


def test_a_lap_log_reads_back_with_its_own_columns(tmp_path):
    n = 6
    lap = LapLog(
        **_columns(n),
        s_ref=np.arange(n, dtype=float),
        ey=np.zeros(n),
        vx_ref=np.full(n, 20.0),
        s_track=np.arange(n, dtype=float),
        solve_ms=np.ones(n),
        in_lap=np.arange(n) > 2,
    )
    lap.save(str(tmp_path / "lap.npz"))
    back = LapLog.load(tmp_path / "lap.npz")
    assert back.theta is None
    assert back.in_lap.dtype == bool
    np.testing.assert_array_equal(back.in_lap, lap.in_lap)
    np.testing.assert_array_equal(back.s_ref, lap.s_ref)
    with pytest.raises(ModelError, match="ey has 2 samples"):
        LapLog(**{**vars(lap), "ey": np.zeros(2)})
