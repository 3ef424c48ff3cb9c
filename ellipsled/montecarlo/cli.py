"""Command line of the Monte Carlo campaign, and the bridge for ``ellipsled batch
--from-campaign DIR --run ID`` (one run rebuilt from its record)."""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import NamedTuple

from common import argtypes
from common.argtypes import nonneg_int
from common.model import Scenario

from .campaign import MAX_RUNS


def add_montecarlo_parser(subparsers) -> argparse.ArgumentParser:
    """``ellipsled montecarlo <campaign> --runs N --out DIR [--scheduler ADDRESS]
    [--workers K] [--duration S] [--seed S]``."""
    p = subparsers.add_parser("montecarlo", help="dispersed Monte Carlo campaign on Dask (local or a cluster)",
                              description=main.__doc__)
    p.add_argument("campaign", help="campaign name (data/campaigns) or .toml path")
    p.add_argument("--runs", type=argtypes.int_range(1, MAX_RUNS), default=None, help="number of runs (default: the campaign's)")
    p.add_argument("--out", required=True, help="campaign folder: results.parquet, summary.md, plots; "
                                                "an existing one is resumed (with --pin: the scenario folder)")
    p.add_argument("--pin", type=nonneg_int, nargs="+", default=None, metavar="ID",
                   help="fly nothing: write these runs as scenario files <campaign>-<seed>-run<ID>.toml in --out "
                        "(e.g. data/scenarios/mc; fly one with `ellipsled batch mc/<file stem>`)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="existing Dask scheduler, e.g. tcp://host:8786 (default: an embedded local cluster)")
    tls = p.add_argument_group("TLS to the scheduler (mutual; the same files as `dask scheduler|worker "
                               "--tls-ca-file --tls-cert --tls-key`; `ellipsled pki init DIR` makes dask.pem)")
    tls.add_argument("--tls-ca-file", default=None, metavar="PEM", help="CA certificate(s)")
    tls.add_argument("--tls-cert", default=None, metavar="PEM", help="this client's certificate")
    tls.add_argument("--tls-key", default=None, metavar="PEM", help="this client's private key")
    # (a few per core at most: each is a process with its own compiled kernels and run history)
    p.add_argument("--workers", type=argtypes.int_range(1, 4 * (os.cpu_count() or 1)), default=None,
                   help="worker processes of the embedded cluster (default: one per core)")
    p.add_argument("--duration", type=argtypes.duration_s, default=None, help="stop every run after S s of flight")
    p.add_argument("--seed", type=argtypes.seed, default=None, help="master seed (default: the campaign's)")
    p.add_argument("--deploy-trigger", choices=("range", "velocity"), default=None,
                   help="every run's flight software deploys the parachute by this rule: range (range to go used "
                        "up, Mars 2020) or velocity (at a Mach, MSL); default: the campaign's [fsw.deploy]")
    p.add_argument("--flush-s", type=argtypes.timeout_s, default=5.0, help="write finished rows at least this often")
    p.add_argument("--dashboard", action="store_true", help="embedded cluster: Dask dashboard on 127.0.0.1")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=main)
    return p


def main(args) -> int:
    """Run or resume a campaign; Ctrl-C stops cleanly (rerun the same command to resume)."""
    from .engine import run_campaign
    if args.pin:
        from .campaign import load_campaign, pin_runs
        from .campaign import with_deploy_trigger
        camp = load_campaign(args.campaign)
        if args.deploy_trigger:
            camp = with_deploy_trigger(camp, args.deploy_trigger)
        for f in pin_runs(camp, args.pin, args.out, args.seed):
            print(f"wrote {f}")
        return 0
    if args.scheduler and args.workers:
        print("ellipsled montecarlo: --workers applies to the embedded cluster only; ignored with --scheduler",
              file=sys.stderr)
    from common.config import ConfigError
    try:
        security = tls_security(args)
        res = run_campaign(args.campaign, args.out, runs=args.runs, master_seed=args.seed, duration_s=args.duration,
                           scheduler=args.scheduler, workers=args.workers, dashboard=args.dashboard,
                           progress=not args.no_progress, flush_s=args.flush_s, security=security,
                           deploy_trigger=args.deploy_trigger)
    except ConfigError:
        raise
    except (ValueError, OSError) as e:   # a campaign folder of another campaign, an unreachable scheduler...
        print(f"ellipsled montecarlo: {e}", file=sys.stderr)
        return 2
    if res.dashboard:
        print(f"dashboard was at {res.dashboard}")
    if res.interrupted:
        print(f"ellipsled montecarlo: interrupted; {res.recorded} of {res.runs} runs recorded in "
              f"{Path(args.out) / 'results.parquet'}; run the same command again to resume", file=sys.stderr)
        return 130
    print(f"{res.recorded} of {res.runs} runs recorded ({res.new} new, {res.failed_new} of them raised) "
          f"in {res.wall_s:.1f} s; summary: {Path(args.out) / 'summary.md'}")
    return 0


def tls_security(args):
    """distributed's Security for the --tls-* options (None without them): encryption
    required, this client authenticated by its certificate."""
    files = {"--tls-ca-file": args.tls_ca_file, "--tls-cert": args.tls_cert, "--tls-key": args.tls_key}
    if not any(files.values()):
        return None
    missing = [k for k, v in files.items() if not v]
    if missing:
        raise ValueError(f"TLS needs --tls-ca-file, --tls-cert and --tls-key; missing {', '.join(missing)}")
    for opt, path in files.items():
        if not Path(path).is_file():
            raise ValueError(f"{opt}: no such file: {path}")
    if not args.scheduler or not args.scheduler.startswith("tls://"):
        raise ValueError(f"--tls-* need a TLS scheduler address (--scheduler tls://HOST:8786), got {args.scheduler!r}")
    from distributed.security import Security
    return Security(tls_ca_file=args.tls_ca_file, tls_client_cert=args.tls_cert, tls_client_key=args.tls_key,
                    require_encryption=True)


class CampaignRun(NamedTuple):
    scenario: Scenario
    seed: int
    duration_s: float | None
    record: dict


def scenario_for_run(campaign_dir: str | Path, run_id: int) -> CampaignRun:
    """Rebuild run ``run_id`` of a campaign folder from its record: the recorded seed and
    dispersions applied to the campaign's snapshot of its base scenario."""
    from common.model import load_scenario
    from .campaign import apply_dispersion, campaign_base, dispersion_from_columns
    from .engine import RESULTS_DIR, SCENARIO_FILE, read_meta
    from .store import ResultStore
    d = Path(campaign_dir)
    meta = read_meta(d)
    rec = ResultStore(d / RESULTS_DIR).row(run_id)
    base = campaign_base(meta["campaign"], load_scenario(d / SCENARIO_FILE))
    scn = apply_dispersion(base, dispersion_from_columns(rec), rec["seed"], f"{meta['campaign']['name']}-{run_id}")
    return CampaignRun(scn, int(rec["seed"]), meta["duration_s"], rec)


def apply_campaign_run(args) -> None:
    """For ``ellipsled batch --from-campaign DIR --run ID``: set ``args.scenario``,
    ``args.seed`` and ``args.duration`` (unless given) from the run's record."""
    if args.run is None:
        raise ValueError("--from-campaign needs --run ID")
    if getattr(args, "seed", None) is not None:
        raise ValueError("--seed conflicts with --from-campaign (the record holds the seed)")
    r = scenario_for_run(args.from_campaign, args.run)
    args.scenario, args.seed = r.scenario, r.seed
    if getattr(args, "duration", None) is None:
        args.duration = r.duration_s
