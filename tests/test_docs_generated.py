"""The documentation's generated reference pages (parameters, record layouts, CLI) are what
the code gives today: regenerated into a temporary folder, each equals the committed page.

Independent truth for the generator itself: the parameter registry, the codec's registry and
the argparse parsers, read here directly; a page that lost a row or a field would still equal
a regeneration by the same generator, so the second test checks the pages against them.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from ellipsled import docsgen

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def test_committed_generated_pages_equal_a_fresh_generation(tmp_path):
    docsgen.write(tmp_path)
    for page in docsgen.PAGES:
        fresh = (tmp_path / page).read_text()
        committed = (DOCS / page).read_text() if (DOCS / page).exists() else None
        assert committed == fresh, f"docs/{page} is out of date: run `python -m ellipsled.docsgen` (or `make docs`)"


def test_generated_pages_name_every_parameter_record_field_and_subcommand():
    from ellipsled import cli
    from fsw.flightsoftware import declarations
    from fsw.params import ParamRegistry
    from interfaces import codec

    params = (DOCS / "reference" / "parameters.md").read_text()
    reg = ParamRegistry(declarations())
    for r in reg.describe():
        row = next((ln for ln in params.splitlines() if ln.startswith(f"| `{r['name']}` |")), None)
        assert row is not None, r["name"]
        assert ("| yes |" in row) == r["ground_settable"], r["name"]
        if r["param_id"]:
            assert f"`{r['param_id']}`" in row

    records = (DOCS / "reference" / "records.md").read_text()
    for s in codec.REGISTRY.values():
        section = records.split(f"\n## {s.name}\n", 1)[1].split("\n## ", 1)[0]
        assert f"{s.dtype.itemsize} bytes" in section
        for name in s.dtype.names:
            offset = s.dtype.fields[name][1]
            assert f"| {offset} | `{name}` |" in section, f"{s.name}.{name}"

    cli_page = (DOCS / "reference" / "cli.md").read_text()
    for name, _, _ in cli.COMMANDS:
        assert f"\n## ellipsled {name}\n" in cli_page, name
        sub = next(a for a in cli.build_parser([name])._actions if isinstance(a, argparse._SubParsersAction))
        for action in sub.choices[name]._actions:
            for opt in action.option_strings:
                if opt not in ("-h", "--help"):
                    assert f"`{opt}`" in cli_page, f"{name} {opt}"


def test_the_comparison_sees_a_stale_page(tmp_path):
    docsgen.write(tmp_path)
    page = tmp_path / docsgen.PAGES[0]
    page.write_text(page.read_text().replace("| yes |", "| no |", 1))
    assert docsgen.stale(tmp_path) == [docsgen.PAGES[0]]
