"""The flood section's rows (ellipsled/bench/flood.py ``rows``): the listens between the
link's ticks and the datagrams the kernel dropped are shown when the run measured them, and
a run from before the listens (no such figures) keeps its old rows."""
from __future__ import annotations

from ellipsled.bench.flood import rows


def flood_result(**extra) -> dict:
    fl = {"flood_compute_p99_us": 2500.0, "flood_compute_max_us": 3900.0, "quiet_compute_p99_us": 1300.0,
          "flood_groundlink_p99_us": 2100.0, "flood_groundlink_max_us": 2120.0, "flood_slips": 0,
          "flood_state_changes": 0, "flood_peers_added": 0, "flood_fdir_latency_max_s": 0.08,
          "quiet": {"compute_max_us": 3800.0, "listen_max_us": 90.0}, "flood": {"flood": {"sent": 50000}},
          "receive": {}, **extra}
    return {"flood": fl}


def test_the_listen_row_shows_the_kernel_drops_of_the_sent():
    got = rows(flood_result(flood_listen_p99_us=1250.0, flood_listen_max_us=1450.0, flood_kernel_drops=0))
    listen = [r for r in got if "listening between ticks" in r[0]]
    assert len(listen) == 1 and listen[0][1] == "1250 / 1450; 0 dropped", listen
    assert "of 50000 sent" in listen[0][2] and "quiet listen max 90.0" in listen[0][2]


def test_a_run_from_before_the_listens_keeps_its_rows():
    old = rows(flood_result())
    assert not any("listening between ticks" in r[0] for r in old) and len(old) == 4


def test_the_receive_row_shows_the_intake_read_every_control_period_when_measured():
    rc = {"flood_intake": {"p99_us": 1300.0, "genuine_handled": 93, "genuine_sent": 100},
          "flood_previous": {"p99_us": 3300.0, "genuine_handled": 27}, "quiet": {"p99_us": 50.0}}
    every = {"p99_us": 472.0, "genuine_handled": 100, "genuine_sent": 100, "kernel_drops": 0}
    old = [r for r in rows(flood_result(receive=rc)) if r[0].startswith("  receive work")][0]
    new = [r for r in rows(flood_result(receive={**rc, "flood_every_cycle": every})) if r[0].startswith("  receive work")][0]
    assert "every control period" not in old[2] and old[2].endswith("93 / 27 of 100"), old
    assert new[2].endswith("every control period (as the vehicle): p99 472.0 a call, 100 of 100 through, 0 dropped"), new
