"""The ``ellipsled`` command: one entry point, one subcommand per job."""
from __future__ import annotations

import argparse
import sys

from common.config import ConfigError


def _add_plant(sub):
    p = sub.add_parser("plant", help="open-loop plant run: attitude held on the reference by an ideal torque")
    p.add_argument("scenario", nargs="?", default="nominal", help="scenario name (data/scenarios) or .toml path")
    p.add_argument("--out", default="runs/plant", help="output folder (plant_summary.json)")
    p.add_argument("--seed", type=int, default=None)

    def run(a):
        from sim.openloop import main as plant_main
        return plant_main(a)
    p.set_defaults(func=run)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="ellipsled", description=__doc__)
    sub = ap.add_subparsers(dest="cmd", required=True)
    _add_plant(sub)
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
