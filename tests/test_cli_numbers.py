"""Every number on an `ellipsled` command line is checked by the parser against its range: a
value outside it is a usage error naming the option (exit status 2), before any process,
session, allocation or flight starts. Runs whose preallocated history would not fit the
memory budget are refused with the budget named."""
from __future__ import annotations

import subprocess

import pytest

from common.config import ConfigError
from ellipsled import cli
from ellipsled.procs import ELLIPSLED
from ellipsled.sil.variant import prepare


BAD = [
    (["batch", "nominal", "--out", "/nonexistent", "--seed", "-1"], "--seed"),
    (["batch", "nominal", "--out", "/nonexistent", "--duration", "1e300"], "--duration"),
    (["batch", "nominal", "--out", "/nonexistent", "--duration", "1e6"], "--duration"),
    (["batch", "--from-campaign", "/nonexistent", "--run", "-3", "--out", "/nonexistent"], "--run"),
    (["plant", "nominal", "--seed", "-2"], "--seed"),
    (["report", "--out", "/nonexistent", "--seed", "-1"], "--seed"),
    (["montecarlo", "default", "--out", "/nonexistent", "--runs", "1000000000"], "--runs"),
    (["montecarlo", "default", "--out", "/nonexistent", "--workers", "10000"], "--workers"),
    (["montecarlo", "default", "--out", "/nonexistent", "--seed", "-1"], "--seed"),
    (["montecarlo", "default", "--out", "/nonexistent", "--flush-s", "nan"], "--flush-s"),
    *[(["run", "--realtime", "--speed", v], "--speed") for v in ("0", "nan", "-1", "1e-9", "inf")],
    *[(["run", "--fsw-timeout", v], "--fsw-timeout") for v in ("nan", "-1", "0")],
    (["run", "--rt-offset-us", "nan"], "--rt-offset-us"),
    (["run", "--seed", "-1"], "--seed"),
    (["sim", "--speed", "0"], "--speed"),
    (["sim", "--fsw-timeout", "nan"], "--fsw-timeout"),
    (["sim", "--wait-peers", "-1"], "--wait-peers"),
    (["sim", "--resend-s", "nan"], "--resend-s"),
    (["sim", "--miss-periods", "0"], "--miss-periods"),
    (["sim", "--rt-priority", "100"], "--rt-priority"),
    (["sim", "--cpu", "-1"], "--cpu"),
    (["sim", "--cpu", "100000"], "--cpu"),
    (["fsw", "--rt-offset-us", "nan"], "--rt-offset-us"),
    (["fsw", "--frame-wait-us", "-5"], "--frame-wait-us"),
    (["fsw", "--wait-peers", "inf"], "--wait-peers"),
    (["router", "--rt-priority", "0"], "--rt-priority"),
    *[(["batch", "nominal", "--out", "x", "--dt-control", v], "--dt-control") for v in ("0", "nan", "-0.005", "1")],
    (["run", "--dt-control", "0"], "--dt-control"),
    (["report", "--out", "x", "--dt-control", "inf"], "--dt-control"),
    (["pki", "init", "/nonexistent", "--days", "0"], "--days"),
    *[(["gse", "arm", "on", "--timeout", v], "--timeout") for v in ("nan", "-1", "0", "inf", "1e300")],
    (["gse", "inject", "--jet", "1", "--kind", "failed_off", "--retries", "-1"], "--retries"),
    (["gse", "mode", "safe", "--gcs-port", "70000"], "--gcs-port"),
    (["gse", "console", "--gcs-port", "-1"], "--gcs-port"),
    *[(["gse", "console", "--replay", "x.tlog", "--speed", v], "--speed") for v in ("0", "nan", "-1", "inf")],
    (["viz", "--flush-rows", "0"], "--flush-rows"),
    (["viz", "--flush-s", "nan"], "--flush-s"),
    *[(["viz", opt, v], opt) for opt in ("--max-seconds", "--idle-exit-s") for v in ("nan", "-1", "0", "1e300")],
]


@pytest.mark.parametrize("argv,option", BAD, ids=lambda x: " ".join(x) if isinstance(x, list) else x)
def test_a_number_outside_its_range_is_a_usage_error_naming_the_option(argv, option, capsys):
    with pytest.raises(SystemExit) as e:
        cli.build_parser(argv).parse_args(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert f"argument {option}" in err and "must be" in err, err


@pytest.mark.parametrize("module,argv,option", [
    ("ellipsled.bench.flood", ["--target", "udp:127.0.0.1:9", "--rate", "nan"], "--rate"),
    ("ellipsled.bench.flood", ["--target", "udp:127.0.0.1:9", "--rate", "-5"], "--rate"),
    ("ellipsled.bench.flood", ["--target", "udp:127.0.0.1:9", "--seconds", "1e300"], "--seconds"),
    ("ellipsled.bench.flood", ["--target", "udp:127.0.0.1:9", "--seed", "-1"], "--seed"),
    ("ellipsled.bench.jitter", ["--child", "--seconds", "inf"], "--seconds"),
    ("ellipsled.bench.jitter", ["--child", "--priority", "100"], "--priority"),
    ("ellipsled.bench.jitter", ["--child", "--cpu", "100000"], "--cpu"),
    ("ellipsled.bench.latency", ["--echo", "udp", "--port", "70000"], "--port"),
    ("ellipsled.bench.latency", ["--variants", "--n", "0"], "--n"),
    ("ellipsled.bench.latency", ["--variants", "--rate", "nan"], "--rate"),
    ("ellipsled.bench.latency", ["--client", "--kinds", "zenoh,tcp"], "--kinds"),
    ("ellipsled.bench.latency", ["--client", "--kinds", ","], "--kinds"),
], ids=lambda x: " ".join(x) if isinstance(x, list) else x)
def test_a_bench_tools_number_outside_its_range_is_a_usage_error(module, argv, option, capsys, monkeypatch):
    """The benchmark's own tools (python -m ellipsled.bench.<tool>) check their numbers too,
    before they flood, spin or echo anything (what they would do is replaced here, so a
    value let through fails at once instead of running the tool)."""
    import importlib
    mod = importlib.import_module(module)

    def ran(*args, **kwargs):
        raise AssertionError(f"{module} ran with {argv}")
    for work in ("send", "child", "run", "_echo_udp", "_echo_zenoh", "variants", "round_trips"):
        if hasattr(mod, work):
            monkeypatch.setattr(mod, work, ran)
    with pytest.raises(SystemExit) as e:
        mod.main(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert f"argument {option}" in err and "must be" in err, err


@pytest.mark.parametrize("argv", [
    ["gse", "arm", "on", "--timeout", "2.5", "--retries", "0", "--gcs-port", "0"],
    ["gse", "console", "--replay", "x.tlog", "--speed", "20"],
    ["viz", "--flush-rows", "1", "--flush-s", "0.5", "--max-seconds", "60", "--idle-exit-s", "5"],
    ["run", "--realtime", "--speed", "1", "--fsw-timeout", "10", "--rt-offset-us", "-100", "--seed", "0"],
    ["batch", "nominal", "--out", "x", "--seed", "123456789", "--duration", "700"],
    ["montecarlo", "default", "--out", "x", "--runs", "1000", "--workers", "1"],
    ["fsw", "--rt-offset-us", "250", "--frame-wait-us", "3000"],
])
def test_values_within_range_pass(argv):
    cli.build_parser(argv).parse_args(argv)


def test_a_control_period_option_flies_the_scenario_at_that_rate_and_is_passed_to_the_nodes():
    from ellipsled.sil.variant import variant_argv
    base = prepare("case1")
    scn = prepare("case1", dt_control_s=0.005)
    assert scn.dt_control_s == 0.005 and scn.name == "case1-200hz" and scn.substeps == 1
    assert scn.faults == base.faults and scn.max_duration_s == base.max_duration_s
    same = prepare("case1", dt_control_s=0.02)                     # the scenario's own period: unchanged
    assert same.name == base.name and same.dt_control_s == base.dt_control_s
    with pytest.raises(ConfigError, match="integrator steps"):
        prepare("case1", dt_control_s=0.0075)                       # not a whole number of 5-ms steps
    argv = ["run", "case1", "--dt-control", "0.005"]
    a = cli.build_parser(argv).parse_args(argv)
    assert variant_argv(a) == ["--dt-control", "0.005"]
    node = ["fsw", "case1", *variant_argv(a)]
    n = cli.build_parser(node).parse_args(node)
    assert prepare(n.scenario, dt_control_s=n.dt_control).dt_control_s == 0.005


def test_a_huge_duration_ends_with_a_usage_error_not_a_traceback(tmp_path):
    r = subprocess.run(ELLIPSLED + ["batch", "nominal", "--out", str(tmp_path), "--duration", "1e300"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr and "argument --duration" in r.stderr


def test_a_run_whose_history_exceeds_the_memory_budget_is_refused_naming_the_budget():
    from ellipsled.sil.history import HISTORY_BUDGET_BYTES, budget_refusal, row_bytes, rows_for
    dt = 0.02
    longest_rows = HISTORY_BUDGET_BYTES // row_bytes()
    too_long = (longest_rows + 10) * dt
    with pytest.raises(ConfigError) as e:
        prepare("nominal", duration_s=too_long)
    msg = str(e.value)
    assert "--duration" in msg and "memory budget" in msg and "GiB" in msg, msg
    assert budget_refusal((longest_rows - 10) * dt, dt) is None
    # a scenario's own max_duration_s is held to the same budget
    scn = prepare("nominal")
    assert rows_for(scn.max_duration_s, scn.dt_control_s) * row_bytes() <= HISTORY_BUDGET_BYTES


def test_a_campaign_whose_runs_exceed_the_memory_budget_is_refused_before_any_run(tmp_path, monkeypatch):
    import ellipsled.sil.history as history
    from ellipsled.montecarlo.engine import run_campaign
    monkeypatch.setattr(history, "HISTORY_BUDGET_BYTES", 1_000_000, raising=False)   # ~1,100 rows: 22 s
    with pytest.raises(ValueError, match="memory budget"):
        run_campaign("default", tmp_path / "mc", runs=1, duration_s=60.0, workers=1, progress=False)
    assert not list((tmp_path / "mc").rglob("*.parquet"))          # nothing flown


def test_a_campaign_file_asking_for_more_runs_than_the_bound_is_refused(tmp_path):
    from common.config import DATA_DIR
    from ellipsled.montecarlo.campaign import MAX_RUNS, load_campaign
    src = (DATA_DIR / "campaigns" / "default.toml").read_text()
    import re
    path = tmp_path / "big.toml"
    path.write_text(re.sub(r"(?m)^runs = \d+", f"runs = {MAX_RUNS * 1000}", src, count=1))
    with pytest.raises(ConfigError, match=r"campaign\.runs: must be <= "):
        load_campaign(path)
