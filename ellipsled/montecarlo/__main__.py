"""``python -m ellipsled.montecarlo <campaign> --runs N --out DIR ...`` (same as ``ellipsled montecarlo``)."""
import argparse
import sys

from common.config import ConfigError

from .cli import add_montecarlo_parser


def _main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m ellipsled.montecarlo")
    sub = ap.add_subparsers(dest="cmd", required=True)
    add_montecarlo_parser(sub)
    a = ap.parse_args(["montecarlo", *(sys.argv[1:] if argv is None else argv)])
    try:
        return int(a.func(a) or 0)
    except (ConfigError, ValueError) as e:
        print(f"ellipsled montecarlo: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(_main())
