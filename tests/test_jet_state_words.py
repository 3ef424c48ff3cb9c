"""One word per jet state: nominal, failed_off, stuck_on, degraded (and inhibited, the
ground's mask), the dialect's ELLIPSLED_JET_HEALTH names in lower case, in code, scenario
files, commands, telemetry labels and docs (upper case in labels).

The retired words (off, stuck, clear, healthy) are written here, not taken from the
vocabulary, so the scan does not weaken with it. A retired word is found where it names a
jet state: "stuck" and "healthy" anywhere; "off" and "clear" where the expression speaks of
a kind, health, state, fault or injection (not "arm off", "ft off", the "clear" command);
in text, code-formatted, as an alternative of a list ("off | stuck"), in a TOML or command
snippet, or as an upper-case label ("FAILED OFF", "HEALTHY"). A line of text that says
"retired" speaks of the old words and is skipped.
"""
from __future__ import annotations

import ast
import re
import tomllib
from pathlib import Path

import pytest

from common.config import ConfigError
from common.model import load_scenario
from gse.commands import make_request
from interfaces import event_catalogue as cat
from interfaces import records
from interfaces import vocabulary as voc

ROOT = Path(__file__).resolve().parents[1]
STATE_WORDS = tuple(voc.HEALTH_NAMES.values())   # pinned by the test of the state words below
RETIRED = {"off", "stuck", "clear", "healthy"}
ALWAYS = {"stuck", "healthy"}                     # no other meaning as a word of their own here
CODE_TREES = ("fsw", "sim", "gse", "common", "interfaces", "ellipsled", "tests")
SELF = Path(__file__).resolve()
GENERATED = Path("interfaces") / "mavlink" / "generated"
RETIRED_TABLE = "RETIRED_STATE_WORDS"             # the vocabulary's table of them: where they may stand
# what an expression is about when its "off" or "clear" names a jet state
STATE_CONTEXT = re.compile(r"kind|health|state|fault|inject", re.I)
STATE_APIS = {"FaultEvent", "set_fault", "schedule_fault", "override", "identified", "cmd_mark", "check_fault_request"}
COMMAND_WORDS = {"inject", "mark", "--kind"}      # the next word is a jet state
SWITCH_WORDS = {"arm", "ft"}                      # the next word is on or off

_W = "off|stuck|clear|healthy"
_ANY = rf"{_W}|nominal|failed_off|stuck_on|degraded|inhibited"
TEXT_PATTERNS = [
    re.compile(r"\bhealthy\b", re.I),
    re.compile(r"\b(FAILED OFF|STUCK ON|HEALTHY)\b"),                       # a label spelled apart
    re.compile(rf"(?<!`)`({_W})`(?!`)", re.I),                              # code-formatted (not an RST ``name``)
    re.compile(rf"\bkind\s*=\s*[\"']({_W})[\"']", re.I),                    # a TOML fault entry
    re.compile(rf"--kind[ =]+({_W})\b", re.I),                              # the gse command line
    re.compile(rf"\b(inject|mark)\s+(JET\s+)?(\d+|JET|ALL JETS|\{{\w+\}})\s+({_W})\b", re.I),  # console, STATUSTEXT, f-string
    # a list of states: "off | stuck", "off/stuck", "off + stuck", "off, stuck" (not "failed off, stuck on")
    re.compile(rf"(?<![\w-])(?<!failed )({_W})\s*\\?[|/+]\s*({_ANY})\b|\b({_ANY})\s*\\?[|/+]\s*({_W})\b", re.I),
    re.compile(rf"(?<![\w-])(?<!failed )({_W}),\s*({_ANY})\b|\b({_ANY}),\s*({_W})(?![\w-]| on)", re.I),
]


def _top_expression(node, parents):
    """The largest expression holding ``node`` below its statement."""
    while isinstance(parents.get(node), ast.expr) or isinstance(parents.get(node), ast.keyword):
        node = parents[node]
    return node


def _names(tree) -> set[str]:
    out = set()
    for n in ast.walk(tree):
        if isinstance(n, ast.Name):
            out.add(n.id)
        elif isinstance(n, ast.Attribute):
            out.add(n.attr)
        elif isinstance(n, ast.keyword) and n.arg:
            out.add(n.arg)
    return out


def _call_name(call: ast.Call) -> str:
    f = call.func
    return f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""


def _words(nodes) -> list:
    return [e for e in nodes if isinstance(e, ast.Constant) and isinstance(e.value, str)]


def names_a_state(c: ast.Constant, parents) -> bool:
    """Whether the retired word ``c`` names a jet state where it stands."""
    w, parent = c.value.lower(), parents.get(c)
    if w in ALWAYS:
        return True
    seq = parent.args if isinstance(parent, ast.Call) else list(getattr(parent, "elts", ()) or ())
    if isinstance(parent, ast.Dict):
        seq = [k for k in parent.keys if k is not None] + parent.values
    words = [e.value.lower() for e in _words(seq)]
    earlier = [e.value.lower() for e in _words(seq[:seq.index(c)])] if c in seq else []
    if "on" in words or earlier and earlier[-1] in SWITCH_WORDS:
        return False                                  # an on/off switch
    if isinstance(parent, ast.Call) and _call_name(parent) in STATE_APIS | {"get"} or set(earlier) & COMMAND_WORDS:
        return True
    top = _top_expression(c, parents)
    if {e.value.lower() for e in _words(ast.walk(top)) if e is not c} & (set(STATE_WORDS) | set(RETIRED)) - {w}:
        return True                                   # beside other jet-state words
    if w == "clear" and _words(seq)[:1] == [c]:
        return False                                  # the clear command itself
    if isinstance(parent, ast.Subscript) or isinstance(parent, ast.Compare) and any(
            isinstance(op, (ast.In, ast.NotIn)) for op in parent.ops):
        return True                                   # spec["off"], "off" in spec
    return any(STATE_CONTEXT.search(n) for n in _names(top))


def code_findings(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(), str(path))
    parents = {ch: n for n in ast.walk(tree) for ch in ast.iter_child_nodes(n)}
    table = {id(x) for a in ast.walk(tree) if isinstance(a, (ast.Assign, ast.AnnAssign))
             and RETIRED_TABLE in {t.id for t in (a.targets if isinstance(a, ast.Assign) else [a.target])
                                   if isinstance(t, ast.Name)} for x in ast.walk(a)}
    found = []
    for n in ast.walk(tree):
        if isinstance(n, ast.JoinedStr):              # an f-string: its text, each field as {x}
            text = "".join(v.value if isinstance(v, ast.Constant) else "{x}" for v in n.values)
            if any(p.search(text) for p in TEXT_PATTERNS):
                found.append(f"line {n.lineno}: {text[:60]!r}")
            continue
        if not (isinstance(n, ast.Constant) and isinstance(n.value, str)) or id(n) in table:
            continue
        if n.value.lower() in RETIRED:
            if names_a_state(n, parents):
                found.append(f"line {n.lineno}: {n.value!r}")
        elif any(p.search(n.value) for p in TEXT_PATTERNS):
            found.append(f"line {n.lineno}: {n.value[:60]!r}")
    return found


def text_findings(text: str) -> list[str]:
    found = []
    for i, line in enumerate(text.splitlines(), 1):
        if "retired" in line.lower():                 # a line about the retired words themselves
            continue
        if "`on`" in line.lower():                    # an on/off switch or enum
            line = re.sub("`off`", "", line, flags=re.I)
        if any(p.search(line) for p in TEXT_PATTERNS):
            found.append(f"line {i}: {line.strip()[:100]}")
    return found


def code_files(root: Path):
    for t in CODE_TREES:
        for p in sorted((root / t).rglob("*.py")):
            rel = p.relative_to(root)
            if GENERATED not in rel.parents and rel != SELF.relative_to(ROOT):
                yield p


def text_files(root: Path):
    yield from sorted((root / "docs").rglob("*.md"))
    yield from sorted(root.glob("*.md"))
    for t in ("interfaces", "gse", "fsw", "sim"):
        yield from sorted((root / t).rglob("*.md"))
    yield root / "interfaces" / "mavlink" / "ellipsled.xml"
    yield from sorted((root / "data").rglob("*.toml"))
    yield from sorted((root / "docs").rglob("*.json"))


def scan(root: Path) -> dict[str, list[str]]:
    bad = {str(p.relative_to(root)): f for p in code_files(root) for f in [code_findings(p)] if f}
    bad.update({str(p.relative_to(root)): f for p in text_files(root) if p.exists()
                for f in [text_findings(p.read_text())] if f})
    return bad


# ------------------------------------------------------------------ the scan

def test_the_scan_finds_retired_jet_state_words_and_spares_switches_and_the_clear_command(tmp_path):
    (tmp_path / "fsw").mkdir()
    (tmp_path / "fsw" / "m.py").write_text(
        'K = {"clear": 0, "off": 1}\n'                          # a second kind table
        'if kind == "off": pass\n'
        'plant.set_fault(3, "stuck")\n'
        'rig.command("inject", "17", "clear")\n'
        'FaultEvent(1.0, (2,), "off")\n'
        'a = spec["off"]\n'
        'L = "RECONFIG JET 2 STUCK ON"\n'
        'cases = [("off", 1.0, FAILED_OFF), ("clear", 1.0, NOMINAL)]\n'
        'plant.set_fault(0, "clear")\n'
        'ON_OFF = {"on": 1, "off": 0}\n'                         # below: none of these is a jet state
        'rig.command("arm", "off")\n'
        'run_cli(r, key, "ft", "off") == 0 and not r.fsw.allocator.fault_tolerance\n'
        'run_cli(r, key, "clear", "--jet", "4") == 0 and r.fsw.fdir.health_active.state[3] == 0\n'
        'if verb == "clear": pass\n'
        'RETIRED_STATE_WORDS = {"off": "failed_off", "stuck": "stuck_on"}\n'
        'app.submit(f"inject {jet} off")\n')
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "x.md").write_text(
        'kind = "stuck"   # off | stuck | degraded\n'
        'ellipsled gse mark --jet 17 --kind healthy\n'
        '| fault_kind_t | uint8_t | 0 `CLEAR`, 1 `OFF` |\n'
        'inject 17 off; GND INJECT JET 17 OFF\n'
        'faulty jets (off + stuck + degraded)\n'
        '| on_off_t | uint8_t | 0 `OFF`, 1 `ON` |\n'           # below: none of these is a jet state
        'arm on|off, ft on|off; the jet fails off and stays stuck on; switch the jets off.\n'
        'the retired words: `off`, `stuck`\n')
    bad = scan(tmp_path)
    assert sorted(int(f.split(":")[0][5:]) for f in bad["fsw/m.py"]) == [1, 1, 2, 3, 4, 5, 6, 7, 8, 8, 9, 16]
    assert [int(f.split(":")[0][5:]) for f in bad["docs/x.md"]] == [1, 2, 3, 4, 5]


def test_code_telemetry_tables_scenarios_and_docs_use_one_word_per_jet_state():
    assert scan(ROOT) == {}


def test_the_state_words_are_the_dialects_and_labels_and_fault_kinds_use_them():
    assert STATE_WORDS == ("nominal", "failed_off", "stuck_on", "degraded", "inhibited")
    assert set(voc.FAULT_KINDS) == set(STATE_WORDS) - {"inhibited"} == set(voc.FAULT_HEALTH)
    assert set(voc.MARK_KINDS) == set(STATE_WORDS)
    assert set(records.FAULT_NAMES.values()) == set(voc.FAULT_KINDS)
    assert cat.HEALTH.labels == {voc.MARK_KINDS[w]: w.upper() for w in STATE_WORDS}
    assert cat.FAULT.labels == {voc.FAULT_KINDS[w]: w.upper() for w in voc.FAULT_KINDS}
    for ev in cat.CATALOGUE:
        assert not any(re.search(r"\b(FAILED OFF|STUCK ON|HEALTHY)\b", m) for m in ev.messages), ev.name
    for path in sorted((ROOT / "data").rglob("*.toml")):
        kinds = {f.get("kind") for f in tomllib.loads(path.read_text()).get("faults", [])}
        assert kinds <= set(voc.FAULT_KINDS), path


# ------------------------------------------------------------------ old words on input: refused, naming the new

@pytest.mark.parametrize("old", sorted(RETIRED))
def test_a_retired_word_in_a_scenario_file_is_refused_naming_its_replacement(tmp_path, old):
    src = (ROOT / "data" / "scenarios" / "case1.toml").read_text()
    path = tmp_path / "s.toml"
    path.write_text(src.replace('kind = "failed_off"', f'kind = "{old}"'))
    new = voc.RETIRED_STATE_WORDS[old]
    with pytest.raises(ConfigError) as e:
        load_scenario(path)
    assert e.value.field == "faults[0].kind" and f"got {old!r} (renamed {new!r})" in e.value.reason


@pytest.mark.parametrize("old", ["off", "clear", "healthy"])
def test_a_retired_word_on_the_console_is_refused_naming_its_replacement(old):
    verb = "mark" if old == "healthy" else "inject"
    with pytest.raises(ValueError, match=rf"got '{old}' \(renamed '{voc.RETIRED_STATE_WORDS[old]}'\)"):
        make_request(verb, "3", old)


def test_the_plant_and_the_ground_link_refuse_a_retired_fault_kind_naming_its_replacement():
    with pytest.raises(ValueError, match=r"got 'off' \(renamed 'failed_off'\)"):
        records.check_fault_request(3, "off", 1.0)


def test_the_vocabulary_names_the_replacement_of_each_retired_word():
    assert voc.RETIRED_STATE_WORDS == {"off": "failed_off", "stuck": "stuck_on",
                                       "clear": "nominal", "healthy": "nominal"}
