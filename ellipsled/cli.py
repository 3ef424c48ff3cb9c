"""The ``ellipsled`` command: one entry point, one subcommand per job."""
from __future__ import annotations

import argparse
import sys

from common import rt

# Every ellipsled process runs its numerics single-threaded (lean, deterministic hot loops,
# two processes on two cores): pinned before NumPy or numba load their thread pools.
rt.single_threaded_numerics()

from common import argtypes  # noqa: E402
from common.config import ConfigError  # noqa: E402


def _add_plant(sub):
    p = sub.add_parser("plant", help="open-loop plant run: attitude held on the reference by an ideal torque")
    p.add_argument("scenario", nargs="?", default="nominal", help="scenario name (data/scenarios) or .toml path")
    p.add_argument("--out", default="runs/plant", help="output folder (plant_summary.json)")
    p.add_argument("--seed", type=argtypes.seed, default=None)

    def run(a):
        from sim.openloop import main as plant_main
        return plant_main(a)
    p.set_defaults(func=run)


def _add_batch(sub):
    from ellipsled.runlib import EXIT_CODES_HELP
    p = sub.add_parser("batch", help="fly a scenario: plant and FSW in one process, lockstep",
                       epilog=EXIT_CODES_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scenario", nargs="?", default=None, help="scenario name (data/scenarios) or .toml path")
    p.add_argument("--out", required=True, help="output folder (summary.json, history.npz, PNG plots)")
    p.add_argument("--from-campaign", metavar="DIR", default=None,
                   help="re-fly one run of a Monte Carlo campaign folder from its record")
    p.add_argument("--run", type=argtypes.nonneg_int, default=None, metavar="ID", help="run_id within --from-campaign")
    p.add_argument("--seed", type=argtypes.seed, default=None)
    p.add_argument("--ft-off", action="store_true", help="fault tolerance off (paper figure 5)")
    p.add_argument("--duration", type=argtypes.duration_s, default=None, help="stop after S seconds of simulated time")
    p.add_argument("--no-plots", action="store_true")
    p.add_argument("--rrd", action="store_true", help="also write DIR/run.rrd, the Rerun recording of the run")
    from ellipsled.sil.variant import add_variant_arguments
    add_variant_arguments(p)

    def run(a):
        if a.from_campaign is not None:
            if a.scenario is not None:
                p.error("give a scenario or --from-campaign DIR --run ID, not both")
            from ellipsled.montecarlo import apply_campaign_run
            try:
                apply_campaign_run(a)      # sets a.scenario (a Scenario), a.seed, a.duration
            except ValueError as e:
                p.error(str(e))
        elif a.scenario is None:
            p.error("a scenario is required (or --from-campaign DIR --run ID)")
        from ellipsled.batch import main as batch_main
        return batch_main(a)
    p.set_defaults(func=run)


def _add_report(sub):
    p = sub.add_parser("report", help="fly every paper case and write report.md (paper claims vs measured)")
    p.add_argument("--out", required=True)
    p.add_argument("--seed", type=argtypes.seed, default=None)
    p.add_argument("--duration", type=argtypes.duration_s, default=None, help="stop after S seconds of simulated time")
    p.add_argument("--reuse", action="store_true",
                   help="write the report from the runs a previous report left in OUT/runs (nothing flown)")
    p.add_argument("--dt-control", type=argtypes.float_range(1e-3, 0.1), default=None, metavar="S",
                   help="control period [s] instead of the scenarios' (e.g. 0.005: 200 Hz)")

    def run(a):
        from ellipsled.report import main as report_main
        return report_main(a)
    p.set_defaults(func=run)


def _add_params(sub):
    p = sub.add_parser("params", help="the FSW parameters: MAVLink id, owner, unit, bounds, default, description")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--markdown", action="store_true", help="the table of interfaces/mavlink/README.md")
    g.add_argument("--json", action="store_true", help="one object per parameter (machine-readable metadata)")

    def run(a):
        import json
        from fsw.flightsoftware import declarations
        from fsw.params import ParamRegistry
        reg = ParamRegistry(declarations())
        if a.json:
            print(json.dumps(reg.describe(), indent=1))
        elif a.markdown:
            print(reg.markdown(), end="")
        else:
            for r in reg.describe():
                bounds = "|".join(r["choices"]) if r["choices"] else f"[{r['min']:g}, {r['max']:g}]"
                print(f"{r['param_id'] or '(not settable)':<17} {r['name']:<27} {r['default']!s:<9} {bounds} {r['unit']}")
    p.set_defaults(func=run)


def _add_run(sub):
    from ellipsled.runlib import EXIT_CODES_HELP
    from ellipsled.sil import launcher
    p = sub.add_parser("run", help="the SIL: plant, flight software and viewers as processes over Zenoh",
                       epilog=EXIT_CODES_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    launcher.add_arguments(p)
    p.set_defaults(func=launcher.main)


# The process shells get their own parsers: a SIL process loads its shell, not the launcher's judging.
def _add_sim(sub):
    from ellipsled.sil import sim_node
    p = sub.add_parser("sim", help="the plant process of the SIL")
    sim_node.add_arguments(p)
    p.set_defaults(func=sim_node.main)


def _add_fsw(sub):
    from ellipsled.sil import fsw_node
    p = sub.add_parser("fsw", help="the flight-software process of the SIL")
    fsw_node.add_arguments(p)
    p.set_defaults(func=fsw_node.main)


def _add_viz(sub):
    def viz(a):
        from gse.viz.bridge import bridge_main
        return bridge_main(a)
    from gse.viz.bridge import add_arguments as viz_arguments
    p = sub.add_parser("viz", help="the Rerun bridge: Zenoh truth/state/events -> Rerun")
    viz_arguments(p)
    p.set_defaults(func=viz)


def _add_gse(sub):
    from gse.cli import add_gse_parser
    add_gse_parser(sub)


def _add_router(sub):
    from ellipsled.net.router import add_router_parser
    add_router_parser(sub)


def _add_pki(sub):
    from ellipsled.net.pki import add_pki_parser
    add_pki_parser(sub)


def _add_montecarlo(sub):
    from ellipsled.montecarlo import add_montecarlo_parser
    add_montecarlo_parser(sub)


def _add_bench(sub):
    from ellipsled.bench.suite import add_bench_parser
    add_bench_parser(sub)


# (subcommand, its one-line help, the function adding its parser in full). Only the chosen
# subcommand's modules are imported: building every parser would import the batch runner, the
# SIL, Rerun and the ground station (seconds) before any command starts.
COMMANDS: tuple[tuple[str, str, object], ...] = (
    ("plant", "open-loop plant run: attitude held on the reference by an ideal torque", _add_plant),
    ("batch", "fly a scenario: plant and FSW in one process, lockstep", _add_batch),
    ("report", "fly every paper case and write report.md (paper claims vs measured)", _add_report),
    ("params", "the FSW parameters: MAVLink id, owner, unit, bounds, default, description", _add_params),
    ("gse", "ground station: console and scripted commands (MAVLink 2, signed)", _add_gse),
    ("run", "the SIL: plant, flight software and viewers as processes over Zenoh", _add_run),
    ("sim", "the plant process of the SIL", _add_sim),
    ("fsw", "the flight-software process of the SIL", _add_fsw),
    ("viz", "the Rerun bridge: Zenoh truth/state/events -> Rerun", _add_viz),
    ("router", "the Zenoh router of a SIL across machines (TLS, access control)", _add_router),
    ("pki", "certificates for Zenoh's mutual TLS (a CA and one per role)", _add_pki),
    ("montecarlo", "dispersed Monte Carlo campaign on Dask (local or a cluster)", _add_montecarlo),
    ("bench", "benchmark suite: every figure next to its baseline, JSON + table", _add_bench),
)


def build_parser(argv: list[str]) -> argparse.ArgumentParser:
    """The parser, in full for the subcommand ``argv`` names (its first word that is not an
    option) and as a name and help line for the others (enough for ``--help`` and for
    argparse's choice of subcommand)."""
    chosen = next((w for w in argv if not w.startswith("-")), None)
    ap = argparse.ArgumentParser(prog="ellipsled", description=__doc__)
    sub = ap.add_subparsers(dest="cmd", required=True)
    for name, hlp, add in COMMANDS:
        if name == chosen:
            add(sub)
        else:
            sub.add_parser(name, help=hlp)
    return ap


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    ap = build_parser(argv)
    a = ap.parse_args(argv)
    try:
        return int(a.func(a) or 0)
    except ConfigError as e:
        print(f"ellipsled: configuration error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("ellipsled: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
