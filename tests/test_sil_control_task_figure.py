"""ellipsled/sil/launcher.py control_task_us: sil.json's control task figure is taken over every
tick the FSW node saved (fsw_timing.npz), not over the executive's ring of recent cycles."""
from __future__ import annotations

import numpy as np

from ellipsled.sil.launcher import control_task_us


def test_the_control_task_figure_covers_every_tick_saved_and_skips_ticks_without_it(tmp_path):
    # 10,000 ticks (more than the executive's 4,096-cycle ring): the slow ones all early
    c = np.full(10_000, 50_000, dtype=np.int64)
    c[:200] = 900_000                      # the first 2 %: 900 us
    c[5] = -1                              # a tick whose control task did not run
    np.savez_compressed(tmp_path / "fsw_timing.npz", jitter_ns=np.zeros(10_000, np.int64), control_ns=c,
                        frame_age_ns=np.zeros(0, np.int64))
    f = control_task_us(tmp_path)
    assert f["runs"] == 9_999 and f["p50"] == 50.0 and f["max"] == 900.0
    assert f["p99"] == 900.0               # the early slow ticks count (the ring's last 4,096 hold none)


def test_no_figure_without_saved_control_times(tmp_path):
    assert control_task_us(tmp_path) is None                       # no file
    np.savez_compressed(tmp_path / "fsw_timing.npz", jitter_ns=np.zeros(3, np.int64),
                        frame_age_ns=np.zeros(0, np.int64))
    assert control_task_us(tmp_path) is None                       # an older node's file
    np.savez_compressed(tmp_path / "fsw_timing.npz", jitter_ns=np.zeros(3, np.int64),
                        control_ns=np.full(3, -1, np.int64), frame_age_ns=np.zeros(0, np.int64))
    assert control_task_us(tmp_path) is None                       # no tick ran it


def test_the_duty_cycle_lps_cycles_are_counted_and_the_p99_given_without_them(tmp_path):
    c = np.full(500, 50_000, dtype=np.int64)
    lp = np.zeros(500, dtype=bool)
    c[1:29], lp[1:29] = 200_000, True      # the LP's cycles: 28 of 500, more than 1 %
    c[3], lp[3] = -1, False                # a tick without the control task
    np.savez_compressed(tmp_path / "fsw_timing.npz", jitter_ns=np.zeros(500, np.int64), control_ns=c,
                        lp_cycle=lp, frame_age_ns=np.zeros(0, np.int64))
    f = control_task_us(tmp_path)
    assert f["runs"] == 499 and f["p99"] == 200.0
    assert f["lp_cycles"] == 27 and f["p99_without_lp"] == 50.0


def test_a_slow_spell_shows_in_the_highest_tenth_and_a_slower_run_in_all_three(tmp_path):
    rng = np.random.default_rng(7)
    c = (20_000 + rng.integers(0, 2_000, 3_000)).astype(np.int64)
    c[1_800:2_100] += 25_000               # a slow spell: one tenth of the run, 45 us instead of 20
    np.savez_compressed(tmp_path / "fsw_timing.npz", jitter_ns=np.zeros(3_000, np.int64), control_ns=c,
                        frame_age_ns=np.zeros(0, np.int64))
    t = control_task_us(tmp_path)["p50_by_tenth"]
    assert 20.0 <= t["lowest"] <= t["median"] <= 22.0 and 45.0 <= t["highest"] <= 47.0
    np.savez_compressed(tmp_path / "fsw_timing.npz", jitter_ns=np.zeros(3_000, np.int64), control_ns=c * 2,
                        frame_age_ns=np.zeros(0, np.int64))
    slower = control_task_us(tmp_path)["p50_by_tenth"]
    assert slower["lowest"] == 2 * t["lowest"] and slower["median"] == 2 * t["median"]


def test_no_tenths_under_a_hundred_ticks(tmp_path):
    np.savez_compressed(tmp_path / "fsw_timing.npz", jitter_ns=np.zeros(99, np.int64),
                        control_ns=np.full(99, 50_000, np.int64), frame_age_ns=np.zeros(0, np.int64))
    assert control_task_us(tmp_path)["p50_by_tenth"] is None
