"""One home for every shared word: the import directions between the trees, and the jet
count, health states, fault kinds, modes, severities and endpoints defined only in
interfaces/vocabulary.py (read from the dialect XML where the wire defines them).

Independent truth: the source files' syntax trees (every import statement, every literal),
and pymavlink's generated bindings for the numbers MAVLink's common.xml fixes.
"""
from __future__ import annotations

import ast
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from interfaces import vocabulary as voc
from interfaces.mavlink import dialect as mav

from tests import import_graph

ROOT = Path(__file__).resolve().parents[1]
TREES = ("fsw", "sim", "gse", "common", "interfaces", "ellipsled")
# tree -> trees it must not import (the FSW never sees the plant or the ground station's
# code; the plant and the ground see the FSW only through interfaces/)
FORBIDDEN = {
    "fsw": {"sim", "gse", "ellipsled"},
    "sim": {"fsw", "gse", "ellipsled"},
    "gse": {"fsw", "sim", "ellipsled"},
    "common": {"fsw", "sim", "gse", "ellipsled"},
    "interfaces": {"fsw", "sim", "gse", "ellipsled"},
}
# The SIL's process shells -> the tree each flies. A shell depends on its tree, interfaces/
# and common/, and on shell helpers in ellipsled/sil/ that obey the same rule; the judging
# (figures of merit, summaries, fault-free twins) stays with the launcher, which runs after.
SHELLS = {"ellipsled.sil.fsw_node": "fsw", "ellipsled.sil.sim_node": "sim"}
SHELL_HELPERS = "ellipsled.sil."
LAUNCHER = "ellipsled.sil.launcher"
VOCABULARY = ROOT / "interfaces" / "vocabulary.py"
GENERATED = import_graph.GENERATED
MODULES = import_graph.modules()
NAMES = {p: name for name, p in MODULES.items()}


def sources(*trees):
    for t in trees:
        for p in sorted((ROOT / t).rglob("*.py")):
            if GENERATED not in p.parents:
                yield p


def imported_trees(path: Path) -> set[str]:
    """Our top-level packages a module imports, anywhere in it (function bodies too)."""
    return {m.split(".")[0] for m in import_graph.imports_of(NAMES.get(path, path.stem), path, MODULES)}


def test_the_import_direction_test_sees_a_forbidden_import(tmp_path):
    bad = tmp_path / "m.py"
    bad.write_text("def f():\n    from fsw.health import JetHealth\n    import sim.plant as p\n")
    assert imported_trees(bad) == {"fsw", "sim"}


@pytest.mark.parametrize("tree", sorted(FORBIDDEN))
def test_no_tree_imports_across_the_interfaces(tree):
    bad = {}
    for p in sources(tree):
        hit = imported_trees(p) & FORBIDDEN[tree]
        if hit:
            bad[str(p.relative_to(ROOT))] = sorted(hit)
    assert bad == {}, f"{tree}/ must not import {sorted(FORBIDDEN[tree])}"


def shell_violations(graph: dict[str, set[str]], shell: str, tree: str) -> dict[str, list[str]]:
    """Modules the process shell ``shell`` reaches that it may not: module -> the import path to it."""
    allowed = {tree, "interfaces", "common"}
    bad = {}
    for m in import_graph.reachable(graph, shell, with_packages=True):
        helper = m in ("ellipsled", "ellipsled.sil") or (m.startswith(SHELL_HELPERS) and m != LAUNCHER)
        if m.split(".")[0] not in allowed and not helper:
            bad[m] = import_graph.import_path(graph, shell, m)
    return bad


@pytest.mark.parametrize("shell", sorted(SHELLS))
def test_the_process_shells_depend_only_on_their_tree_interfaces_common_and_shell_helpers(shell):
    bad = shell_violations(import_graph.graph(), shell, SHELLS[shell])
    assert bad == {}, f"{shell} must not reach: " + "; ".join(" -> ".join(p) for p in bad.values())


def test_the_shell_check_sees_judging_or_the_other_tree_reached_through_a_helper():
    g = import_graph.graph()
    g["ellipsled.sil.history"] = g["ellipsled.sil.history"] | {"ellipsled.metrics"}     # a planted judging import
    g["ellipsled.sil.variant"] = g["ellipsled.sil.variant"] | {"fsw.params"}            # the FSW, for the plant
    bad = shell_violations(g, "ellipsled.sil.sim_node", "sim")
    assert bad["ellipsled.metrics"] == ["ellipsled.sil.sim_node", "ellipsled.sil.history", "ellipsled.metrics"]
    assert "fsw.params" in bad and "ellipsled.metrics" in shell_violations(g, "ellipsled.sil.fsw_node", "fsw")
    assert "fsw.params" not in shell_violations(g, "ellipsled.sil.fsw_node", "fsw")


# ------------------------------------------------------------------ one definition

KIND_WORDS = set(voc.FAULT_KINDS) | set(voc.MARK_KINDS) | set(voc.HEALTH_NAMES.values()) | {"failed"}
PORTS = {voc.parse_udp(voc.DEFAULT_GCS, "")[1], voc.parse_udp(voc.DEFAULT_VEHICLE, "")[1]}
MODE_WORDS = {m.name for m in voc.Mode} | {m.name.lower() for m in voc.Mode}


def literal_findings(path: Path, expectations: bool = False) -> list[str]:
    """Places that define shared vocabulary again: an assignment of the jet count, a
    collection literal of two or more kind or mode words, an endpoint port. ``expectations``
    (a test module): what an ``assert`` states is the test's own truth, not a definition."""
    tree = ast.parse(path.read_text(), str(path))
    asserted = {id(n) for a in ast.walk(tree) if expectations and isinstance(a, ast.Assert) for n in ast.walk(a)}
    found = []
    for node in ast.walk(tree):
        if id(node) in asserted:
            continue
        if isinstance(node, (ast.Assign, ast.AnnAssign)) and isinstance(node.value, ast.Constant) \
                and node.value.value == voc.N_JETS and type(node.value.value) is int:
            found.append(f"line {node.lineno}: = {voc.N_JETS}")
        if isinstance(node, (ast.Dict, ast.Tuple, ast.List, ast.Set)):
            elts = node.keys + node.values if isinstance(node, ast.Dict) else node.elts
            words = {e.value for e in elts if isinstance(e, ast.Constant) and isinstance(e.value, str)}
            if len(words & KIND_WORDS) >= 2 or len(words & MODE_WORDS) >= 2:
                found.append(f"line {node.lineno}: {sorted(words & (KIND_WORDS | MODE_WORDS))}")
        if isinstance(node, ast.Constant) and (node.value in PORTS or isinstance(node.value, str)
                                               and re.fullmatch(r"(udp:)?[\w.]+:(\d+)", node.value)
                                               and int(node.value.rsplit(":", 1)[1]) in PORTS):
            found.append(f"line {node.lineno}: endpoint {node.value!r}")
    return found


def test_the_literal_scan_finds_a_second_definition(tmp_path):
    p = tmp_path / "m.py"
    p.write_text('N_JETS = 18\nK = {"failed": 1, "stuck_on": 2}\nM = {0: "STANDBY", 1: "ENTRY"}\nG = "udp:h:14550"\n'
                 'def test_x():\n    assert f() == {"failed_off": 1, "stuck_on": 2}\n')
    assert len(literal_findings(p)) == 5
    assert len(literal_findings(p, expectations=True)) == 4     # the assert's table is the test's truth


def test_jet_count_kind_mode_and_endpoint_words_are_defined_only_in_the_vocabulary():
    bad = {str(p.relative_to(ROOT)): f for p in sources(*TREES) if p != VOCABULARY
           for f in [literal_findings(p)] if f}
    bad.update({str(p.relative_to(ROOT)): f for p in sources("tests") for f in [literal_findings(p, True)] if f})
    assert bad == {}


def test_vocabulary_is_read_from_the_dialect():
    root = ET.parse(ROOT / "interfaces" / "mavlink" / "ellipsled.xml").getroot()
    enums = {e.get("name"): {x.get("name"): int(x.get("value")) for x in e.iter("entry")} for e in root.iter("enum")}
    assert {f"ELLIPSLED_JET_HEALTH_{s.name}": int(s) for s in voc.JetState} == enums["ELLIPSLED_JET_HEALTH"]
    assert {f"ELLIPSLED_MODE_{m.name}": int(m) for m in voc.Mode} == enums["ELLIPSLED_MODE"]
    assert voc.HEALTH_NAMES[voc.FAILED_OFF] == "failed_off" and voc.MARK_KINDS["nominal"] == voc.NOMINAL
    # the generated bindings agree, and so do MAVLink's own numbers written in the vocabulary
    assert len(mav.MAVLink_ellipsled_jet_status_message(0, 0, 0, *([[0] * voc.N_JETS] + [[0.0] * voc.N_JETS]
                                                                  + [[0] * voc.N_JETS, [0.0] * voc.N_JETS])).health) \
        == voc.N_JETS == mav.MAVLink_ellipsled_jet_status_message.array_lengths[3]
    assert {s.name: int(s) for s in voc.Severity} == {
        k.removeprefix("MAV_SEVERITY_"): v for k, v in ((e.name, c) for c, e in mav.enums["MAV_SEVERITY"].items())
        if k.startswith("MAV_SEVERITY_") and not k.endswith("ENUM_END")}
    assert voc.FAULT_KINDS == {"nominal": mav.FAILURE_TYPE_OK, "failed_off": mav.FAILURE_TYPE_OFF,
                               "stuck_on": mav.FAILURE_TYPE_STUCK, "degraded": mav.FAILURE_TYPE_WRONG}


def test_parse_udp_accepts_the_default_endpoints_and_names_a_bad_one():
    assert voc.parse_udp(voc.DEFAULT_GCS, "gcs") == ("127.0.0.1", 14550)
    assert voc.parse_udp(voc.DEFAULT_VEHICLE, "vehicle") == ("127.0.0.1", 14555)
    with pytest.raises(ValueError, match="bind: port must be in 0..65535"):
        voc.parse_udp("udp:127.0.0.1:70000", "bind")
