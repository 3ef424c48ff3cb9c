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
VOCABULARY = ROOT / "interfaces" / "vocabulary.py"
GENERATED = ROOT / "interfaces" / "mavlink" / "generated"


def sources(*trees):
    for t in trees:
        for p in sorted((ROOT / t).rglob("*.py")):
            if GENERATED not in p.parents:
                yield p


def imported_trees(path: Path) -> set[str]:
    """Top-level packages a module imports, anywhere in it (function bodies too)."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out.update(a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.add(node.module.split(".")[0])
    return out


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


# ------------------------------------------------------------------ one definition

KIND_WORDS = set(voc.FAULT_KINDS) | set(voc.MARK_KINDS) | set(voc.HEALTH_NAMES.values()) | {"failed"}
PORTS = {voc.parse_udp(voc.DEFAULT_GCS, "")[1], voc.parse_udp(voc.DEFAULT_VEHICLE, "")[1]}
MODE_WORDS = {m.name for m in voc.Mode} | {m.name.lower() for m in voc.Mode}


def literal_findings(path: Path) -> list[str]:
    """Places that define shared vocabulary again: an assignment of the jet count, a
    collection literal of two or more kind or mode words, an endpoint port."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
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
    p.write_text('N_JETS = 18\nK = {"failed": 1, "stuck_on": 2}\nM = {0: "STANDBY", 1: "ENTRY"}\nG = "udp:h:14550"\n')
    assert len(literal_findings(p)) == 4


def test_jet_count_kind_mode_and_endpoint_words_are_defined_only_in_the_vocabulary():
    bad = {str(p.relative_to(ROOT)): f for p in sources(*TREES) if p != VOCABULARY
           for f in [literal_findings(p)] if f}
    assert bad == {}


def test_vocabulary_is_read_from_the_dialect():
    root = ET.parse(ROOT / "interfaces" / "mavlink" / "ellipsled.xml").getroot()
    enums = {e.get("name"): {x.get("name"): int(x.get("value")) for x in e.iter("entry")} for e in root.iter("enum")}
    assert {f"ELLIPSLED_JET_HEALTH_{s.name}": int(s) for s in voc.JetState} == enums["ELLIPSLED_JET_HEALTH"]
    assert {f"ELLIPSLED_MODE_{m.name}": int(m) for m in voc.Mode} == enums["ELLIPSLED_MODE"]
    assert voc.HEALTH_NAMES[voc.FAILED_OFF] == "failed_off" and voc.MARK_KINDS["healthy"] == voc.NOMINAL
    # the generated bindings agree, and so do MAVLink's own numbers written in the vocabulary
    assert len(mav.MAVLink_ellipsled_jet_status_message(0, 0, 0, *([[0] * voc.N_JETS] + [[0.0] * voc.N_JETS]
                                                                  + [[0] * voc.N_JETS, [0.0] * voc.N_JETS])).health) \
        == voc.N_JETS == mav.MAVLink_ellipsled_jet_status_message.array_lengths[3]
    assert {s.name: int(s) for s in voc.Severity} == {
        k.removeprefix("MAV_SEVERITY_"): v for k, v in ((e.name, c) for c, e in mav.enums["MAV_SEVERITY"].items())
        if k.startswith("MAV_SEVERITY_") and not k.endswith("ENUM_END")}
    assert voc.FAULT_KINDS == {"clear": mav.FAILURE_TYPE_OK, "off": mav.FAILURE_TYPE_OFF,
                               "stuck": mav.FAILURE_TYPE_STUCK, "degraded": mav.FAILURE_TYPE_WRONG}


def test_parse_udp_accepts_the_default_endpoints_and_names_a_bad_one():
    assert voc.parse_udp(voc.DEFAULT_GCS, "gcs") == ("127.0.0.1", 14550)
    assert voc.parse_udp(voc.DEFAULT_VEHICLE, "vehicle") == ("127.0.0.1", 14555)
    with pytest.raises(ValueError, match="bind: port must be in 0..65535"):
        voc.parse_udp("udp:127.0.0.1:70000", "bind")
