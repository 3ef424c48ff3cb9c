"""The ``ellipsled`` command builds only the chosen subcommand's parser: ``--help`` and every
other subcommand start without importing the batch runner, the SIL, Rerun or the ground
station; the one-line helps of the lazy parser are those of the full parsers."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from ellipsled import cli

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("ellipsled.batch", "ellipsled.sil.launcher", "fsw.flightsoftware", "gse.cli", "gse.viz.bridge",
         "rerun", "zenoh", "ellipsled.montecarlo", "ellipsled.bench.suite")


def _helps(ap):
    sub = next(a for a in ap._actions if a.dest == "cmd")
    return {c.dest: c.help for c in sub._choices_actions}


def test_lazy_helps_equal_the_full_parsers():
    stubs = _helps(cli.build_parser(["--help"]))
    assert list(stubs) == [name for name, _, _ in cli.COMMANDS]
    for name, _, _ in cli.COMMANDS:
        full = _helps(cli.build_parser([name]))
        assert full[name] == stubs[name], name
        assert set(full) == set(stubs), name


def test_help_imports_no_subcommand_module():
    code = ("import sys; from ellipsled import cli; cli.build_parser(['--help']); "
            f"print([m for m in {HEAVY!r} if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120,
                         env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_chosen_subcommand_is_parsed_in_full():
    a = cli.build_parser(["batch", "case1", "--out", "x"]).parse_args(["batch", "case1", "--out", "x"])
    assert a.cmd == "batch" and a.scenario == "case1" and a.out == "x" and callable(a.func)


def test_every_process_started_by_hand_defaults_to_the_same_key_prefix():
    """sim, fsw, the launcher and the viewer, each with its defaults, meet on one prefix."""
    import argparse

    from ellipsled.sil import launcher
    from ellipsled.sil.common import add_common_arguments
    from gse.viz.bridge import add_arguments
    from interfaces.keys import DEFAULT_PREFIX
    prefixes = set()
    for add in (add_common_arguments, add_arguments, launcher.add_arguments):
        p = argparse.ArgumentParser()
        add(p)
        prefixes.add(p.get_default("prefix"))
    assert prefixes == {DEFAULT_PREFIX}
