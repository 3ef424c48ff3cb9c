"""The event catalogue (interfaces/event_catalogue.py) and what is derived from it: the
STATUSTEXT texts (written out here by hand, as the modules produced them before the
catalogue), the events metadata file (the libevents schema's rules, restated here), the
docs table, reading a STATUSTEXT back to its entry; and the call sites (their syntax trees).
"""
from __future__ import annotations

import ast
import json
import re
from pathlib import Path

import pytest

from interfaces import codec
from interfaces import event_catalogue as cat
from interfaces import event_metadata
from interfaces.event_catalogue import BY_NAME, CATALOGUE, EV, F32, TEXT, U8, _ev
from interfaces.vocabulary import DEGRADED, NOMINAL, STUCK_ON, Mode

ROOT = Path(__file__).resolve().parents[1]

# the modules other engineers are moving: their emits keep the text form until then
TEXT_FORM_LEFT: set[str] = set()      # no product module emits a message text of its own


def test_the_catalogue_passes_its_own_check():
    assert cat.check() == []
    assert len(CATALOGUE) == len(BY_NAME) == len(cat.BY_ID) >= 60


def test_the_check_finds_a_broken_catalogue():
    bad = [_ev(1, "fdir", cat.NOTICE, "JET {jet}", "a", jet=U8, name="one"),
           _ev(1, "fdir", cat.NOTICE, "X", "b", name="one"),                           # same id, same name
           _ev(2, "nowhere", cat.NOTICE, "X {y}", "c", x=U8, name="two"),              # source; field; argument
           _ev(3, "fdir", cat.NOTICE, "Y" * 51, "d", name="three"),                    # too long
           _ev(4, "fdir", cat.NOTICE, " ".join(f"{{a{i}}}" for i in range(11)), "e", name="four",
               **{f"a{i}": F32 for i in range(11)}),                                   # 44 bytes of arguments
           _ev(5, "fdir", cat.NOTICE, ("A {t}", "B {t}"), "f", name="five", t=TEXT)]   # two forms, same arguments
    found = " ".join(cat.check(bad))
    for what in ("id 1 also used", "name one also used", "source 'nowhere'", "names ['y']", "['x'] in no message",
                 "longer than 50", "exceed 40 bytes", "same arguments"):
        assert what in found, what


@pytest.mark.parametrize("event, args, text", [
    (EV.MODE_CHANGE, dict(current=Mode.STANDBY, target=Mode.ENTRY, reason="start"), "MODE STANDBY->ENTRY (start)"),
    (EV.MODE_REFUSED, dict(request="TAKE_OFF_NOW_PLEASE"), "MODE TAKE_OFF_NOW UNKNOWN: REFUSED"),
    (EV.MODE_REFUSED, dict(current=Mode.STANDBY, target=Mode.SAFE), "MODE STANDBY->SAFE REFUSED"),
    (EV.FRAME_RANGE, dict(k=-4), "SENSOR FRAME BAD K -4"),
    (EV.FRAME_RANGE, dict(vector=1, value=1.1313708498984762), "SENSOR SIGMA OUT OF RANGE 1.131"),
    (EV.FRAME_NONFINITE, dict(vector=4), "SENSOR FRAME NON-FINITE ACCEL"),
    (EV.SENSORS_STALE, dict(periods=5), "SENSORS STALE (5 PERIODS): JETS HELD OFF"),
    (EV.JET_INHIBIT, dict(jets=0, inhibit=True), "ALL JETS INHIBITED"),
    (EV.JET_INHIBIT, dict(jets=7, inhibit=False), "JET 7 INHIBIT CLEARED"),
    (EV.FDIR_CHAMBER_SKIP, dict(jet=4, count=2), "FDIR SKIPS NON-FINITE CHAMBER JET 4 (x2)"),
    (EV.JET_STUCK_ON, dict(jet=6), "JET 6 STUCK_ON"),
    (EV.FDIR_RECONFIG, dict(jet=2, health=STUCK_ON, override=False), "RECONFIG JET 2 STUCK_ON"),
    (EV.FDIR_RECONFIG, dict(jet=11, health=DEGRADED, eta=0.5123, override=True),
     "RECONFIG JET 11 DEGRADED ETA 0.51 (GND OVERRIDE HO"),                       # cut at 50, as STATUSTEXT did
    (EV.FDIR_OVERRIDE, dict(jet=4, health=NOMINAL), "GND MARK JET 4 NOMINAL"),
    (EV.FDIR_OVERRIDE, dict(jet=4, health=DEGRADED, eta=0.5), "GND MARK JET 4 DEGRADED ETA 0.50"),
    (EV.FDIR_CLEAR, dict(jets=0), "GND CLEAR ALL JETS"),
    (EV.UNEXPLAINED_TORQUE, dict(torque_Nm=221.7), "UNEXPLAINED TORQUE 222 NM"),
    (EV.INJECT, dict(jets=17, kind=1), "GND INJECT JET 17 FAILED_OFF"),
    (EV.INJECT, dict(jets=3, kind=4, eta=0.4), "GND INJECT JET 3 DEGRADED ETA 0.40"),
    (EV.TASK_ERROR, dict(task="control", error="ZeroDivisionError"), "task control: ZeroDivisionError"),
    (EV.CYCLE_SLIP, dict(tick=752, took_ms=28.81, deadline_ms=20.0, task="control", task_ms=28.79),
     "slip k=752 28.8>20ms control 28.8"),
    (EV.CONTROLLABILITY, dict(auth_pos=3.861, auth_neg=3.024, bias_Nm=135.2, trim="0.0"),
     "AUTH +3.86/-3.02 DEG/S2 BIAS 135NM TRIM 0.0DEG"),
    (EV.BANK_REVERSAL, dict(rule=1, dpsi_deg=6.62), "BANK REVERSAL (CORRIDOR) DPSI +6.6 DEG"),
    (EV.GUIDANCE_OVERRUN, dict(what=1), "GUIDANCE CYCLE OVERRUN: COMMAND KEPT"),
    (EV.NPC_PARAM, dict(param="NPC.K_TAU_S", value=20.0), "GUIDANCE NPC.K_TAU_S 20"),
    (EV.FAULT_TOLERANCE, dict(state=False), "GND FAULT TOLERANCE OFF"),
    (EV.LINK_REFUSED, dict(detail="unsigned command 420 from 245/190"), "unsigned command 420 from 245/190"),
    (EV.RX_CRC, {}, "SENSOR PAYLOAD REJECTED: crc"),
])
def test_the_statustext_is_the_text_the_modules_sent_before(event, args, text):
    form, got = event.render(args)
    assert got == text and len(got) <= 50
    assert cat.by_event_id(event.event_id(form.index)) == (event, form)


def test_every_codec_rejection_reason_has_its_event():
    tree = ast.parse((ROOT / "interfaces" / "codec.py").read_text())
    said = {n.args[0].value for n in ast.walk(tree) if isinstance(n, ast.Call) and getattr(n.func, "attr", "") == "_reject"
            and n.args and isinstance(n.args[0], ast.Constant)}
    said |= {n.value.value for n in ast.walk(tree) if isinstance(n, ast.Return) and isinstance(n.value, ast.Constant)
             and isinstance(n.value.value, str)}                               # SequenceGuard.check's reasons
    assert said and said <= set(codec.REJECT_REASONS)
    assert {f"rx_{r}" for r in codec.REJECT_REASONS} <= set(BY_NAME)


def test_docs_events_md_is_the_generated_table():
    assert (ROOT / "docs" / "events.md").read_text(encoding="utf-8") == event_metadata.markdown(), \
        "docs/events.md is out of date: run python -m interfaces.event_metadata"


BASIC = {"uint8_t": 1, "int8_t": 1, "uint16_t": 2, "int16_t": 2, "uint32_t": 4, "int32_t": 4, "uint64_t": 8,
         "int64_t": 8, "float": 4}


def test_the_events_metadata_keeps_the_libevents_schema_rules():
    """validation/schema.json of mavlink/libevents, restated: version 2; components keyed by
    an 8-bit id with a lower-case namespace; enums named ``*_t`` over an integer type, entries
    keyed by value with a lower-case name and a one-line description; events keyed by their
    24-bit sub-id with a name, a one-line message of 1..120 characters, arguments of a basic
    type or a declared enum, at most the 40 bytes of EVENT.arguments."""
    doc = json.loads(event_metadata.metadata_bytes())
    assert set(doc) <= {"version", "components", "translation"} and doc["version"] == 2
    ((cid, comp),) = doc["components"].items()
    assert re.fullmatch(r"[0-9]+", cid) and int(cid) < 256
    assert set(comp) <= {"namespace", "enums", "event_groups", "supported_protocols", "navigation_mode_groups"}
    assert re.fullmatch(r"[a-z][a-z0-9_]*", comp["namespace"])
    for name, enum in comp["enums"].items():
        assert re.fullmatch(r"[a-zA-Z][a-zA-Z0-9_]*_t", name) and set(enum) <= {"type", "description", "entries"}
        assert enum["type"] in BASIC and enum["type"] not in ("float",) and "\n" not in enum["description"]
        names = [e["name"] for e in enum["entries"].values()]
        assert len(set(names)) == len(names)
        for value, entry in enum["entries"].items():
            assert re.fullmatch(r"[0-9]+", value) and int(value) < 256 ** BASIC[enum["type"]]
            assert set(entry) == {"name", "description"} and re.fullmatch(r"[a-z][a-z0-9_]*", entry["name"])
            assert "\n" not in entry["description"]
    ((group, body),) = comp["event_groups"].items()
    assert group == "default" and set(body) == {"events"}
    names = set()
    for sub, ev in body["events"].items():
        assert re.fullmatch(r"[0-9]+", sub) and int(sub) < 1 << 24
        assert set(ev) <= {"name", "message", "description", "type", "instance_arg_index", "arguments"}
        assert re.fullmatch(r"[a-zA-Z][a-zA-Z0-9_]*", ev["name"]) and ev["name"] not in names
        names.add(ev["name"])
        assert re.fullmatch(r"[^\n]{1,120}", ev["message"])
        size = 0
        for arg in ev.get("arguments", []):
            assert set(arg) == {"name", "type"} and re.fullmatch(r"[a-zA-Z][a-zA-Z0-9_]*", arg["name"])
            base = BASIC.get(arg["type"]) or BASIC[comp["enums"][arg["type"]]["type"]]
            size += base
        assert size <= 40
        # every {n} or {n:.d} names an argument; '<', '{' and '\' are escaped elsewhere
        refs = re.findall(r"(?<!\\)\{([^}]*)\}", ev["message"])
        assert all(re.fullmatch(r"[1-9][0-9]*(:\.[0-9]+)?", r) and int(r.split(":")[0]) <= len(ev.get("arguments", []))
                   for r in refs), ev
        assert not re.search(r"(?<!\\)<", ev["message"])
    assert len(body["events"]) == sum(len(e.forms) for e in CATALOGUE)


def _libevents_render(ev: dict, enums: dict, values: list) -> str:
    """A ground station's rendering of one event (libevents' message rules: {n} the n-th
    argument, {n:.d} with d decimals, an enum as its entry's description)."""
    args = ev.get("arguments", [])

    def one(m):
        i, _, dec = m.group(1).partition(":.")
        arg, v = args[int(i) - 1], values[int(i) - 1]
        if arg["type"] in enums:
            return enums[arg["type"]]["entries"][str(v)]["description"]
        return f"{v:.{dec}f}" if dec else str(v)
    return re.sub(r"\{([^}]*)\}", one, ev["message"]).strip()


def test_a_ground_station_shows_the_statustext_from_the_event_and_the_metadata():
    """Where the message has no free text, no significant-digit or signed format, the
    metadata and the EVENT's values give the STATUSTEXT itself."""
    import struct
    doc = json.loads(event_metadata.metadata_bytes())["components"]["1"]
    events, enums = doc["event_groups"]["default"]["events"], doc["enums"]
    samples = {"uint8_t": 7, "uint32_t": 123456, "int64_t": -42, "float": 0.25}
    n = 0
    for e in CATALOGUE:
        for f in e.forms:
            if any(e.args[a].is_text or "g" in spec or "+" in spec for a, spec in f.fields):
                continue
            args = {a: (max(e.args[a].labels) if e.args[a].is_enum else samples[e.args[a].name]) for a, _ in f.fields}
            _, text = e.render(args)
            ev = events[str(e.event_id(f.index) & 0xFFFFFF)]
            packed, values, off = e.pack(f, args), [], 0
            for arg in ev.get("arguments", []):
                t = enums[arg["type"]]["type"] if arg["type"] in enums else arg["type"]
                code = {"uint8_t": "B", "uint16_t": "H", "uint32_t": "I", "int64_t": "q", "float": "f"}[t]
                values.append(struct.unpack_from("<" + code, packed, off)[0])
                off += struct.calcsize(code)
            assert _libevents_render(ev, enums, values)[:50].strip() == text.strip(), (e.name, f.message)
            n += 1
    assert n >= 40


def test_a_statustext_is_read_back_to_its_entry():
    for e in CATALOGUE:
        for f in e.forms:
            if not re.search(r"[A-Za-z0-9]", re.sub(r"\{[^}]*\}", "", f.message)):
                continue                        # nothing but free text: could be any entry's
            args = {a: cat.sample_value(e.args[a]) for a, _ in f.fields}
            _, text = e.render(args)
            assert cat.identify(text) is e, (e.name, text)
            assert cat.identify((text + " (+3 suppressed)")[:50]) is e, (e.name, text)    # a summary, cut
    assert cat.identify("JET 3 FAILED_OFF (+2 suppressed)") is EV.JET_FAILED_OFF
    assert cat.identify("NOT CONTROLLABLE: stuck-on bias 900 N m beyond what t") is EV.NOT_CONTROLLABLE
    assert cat.identify("anything at all") is None


def _old_form_emits(path: Path) -> list[int]:
    """Lines of ``.emit(...)`` calls of the text form (time, severity, source, code, text)."""
    tree = ast.parse(path.read_text(), str(path))
    return [n.lineno for n in ast.walk(tree) if isinstance(n, ast.Call) and getattr(n.func, "attr", "") == "emit"
            and len(n.args) >= 5]


def test_no_emit_passes_a_message_text_outside_the_modules_being_moved():
    found = {}
    for tree in ("fsw", "sim", "gse", "common", "interfaces", "ellipsled"):
        for p in sorted((ROOT / tree).rglob("*.py")):
            lines = _old_form_emits(p)
            if lines:
                found[p.relative_to(ROOT).as_posix()] = lines
    assert set(found) <= TEXT_FORM_LEFT, {k: v for k, v in found.items() if k not in TEXT_FORM_LEFT}
    # and each of those names a catalogue entry by its code
    for rel in found:
        tree = ast.parse((ROOT / rel).read_text())
        for n in ast.walk(tree):
            if isinstance(n, ast.Call) and getattr(n.func, "attr", "") == "emit" and len(n.args) >= 5 \
                    and isinstance(n.args[3], ast.Constant):
                assert n.args[3].value in BY_NAME, (rel, n.lineno, n.args[3].value)
