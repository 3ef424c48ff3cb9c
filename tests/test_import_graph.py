"""No import circle anywhere in our packages, and tests share helpers, not each other.

Truth: the source files' syntax trees (tests/import_graph.py): every import statement, at
module level and inside functions alike — an import put in a function body to dodge a
circle is still a circle. Beside the layering test (tests/test_vocabulary.py), which
checks the directions between the trees and the process shells' dependencies.
"""
from __future__ import annotations

from tests import import_graph


def _named(circles: list[list[str]]) -> str:
    return "; ".join(" -> ".join(c) for c in circles)


def test_no_module_imports_itself_through_others():
    found = import_graph.circles(import_graph.graph())
    assert found == [], f"import circles: {_named(found)}"


def test_the_circle_check_sees_a_circle_closed_inside_a_function(tmp_path):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "runner.py").write_text("from pkg.judge import verdict\n")
    (pkg / "judge.py").write_text("from . import cache\n\ndef verdict():\n    pass\n")
    (pkg / "cache.py").write_text("def fly():\n    from .runner import run\n")
    (pkg / "leaf.py").write_text("import pkg.cache\n")
    found = import_graph.circles(import_graph.graph(tmp_path, ("pkg",)))
    assert found == [["pkg.cache", "pkg.runner", "pkg.judge", "pkg.cache"]], _named(found)


def test_test_modules_import_helpers_not_other_test_modules():
    """A helper two test modules need lives in a helper module (tests/rig.py, tests/procs.py, ...)."""
    bad = {m: sorted(t for t in deps if t.rpartition(".")[2].startswith("test_"))
           for m, deps in import_graph.graph().items() if m.startswith("tests.")}
    assert {m: d for m, d in bad.items() if d} == {}
