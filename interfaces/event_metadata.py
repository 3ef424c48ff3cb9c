"""What is derived from the event catalogue (interfaces/event_catalogue.py) for readers
outside the flight software: the events metadata file of the MAVLink events interface (the
libevents "events" JSON, version 2, that the ground link serves through component metadata
as COMP_METADATA_TYPE_EVENTS) and the table of docs/events.md.

    python -m interfaces.event_metadata                 # rewrite docs/events.md
    python -m interfaces.event_metadata --check         # exit 1 if docs/events.md is out of date
    python -m interfaces.event_metadata --json FILE     # write the events metadata file

In the metadata each form of an entry is one event: sub-id ``id * 10 + form``, name the
entry's (``_2``, ``_3`` ... for its further forms), message with the arguments the EVENT
message carries (``{1}``, ``{2:.2}``: libevents' own syntax); a TEXT argument, which only
the STATUSTEXT of the same event carries, shows as "…". The EVENT shows numbers as libevents
formats them: float32, a fixed number of decimals ("{:.4g}" shows the float in full), no
forced sign ("{:+.1f}" shows -1.0 and 1.0), and not cut at 50 characters.
"""
from __future__ import annotations

import argparse
import json
import re
import string
import sys
from pathlib import Path

from interfaces.event_catalogue import (CATALOGUE, COMPONENT_ID, ENUMS, FORMS, NAMESPACE, TEXT_MARK, EventDef, Form)

METADATA_VERSION = 2                   # libevents events.schema.json: version 2
DOCS = Path(__file__).resolve().parents[1] / "docs" / "events.md"
_DECIMALS = re.compile(r"\+?\.(\d+)f")


def _escape(literal: str) -> str:
    """libevents message escaping: backslash, '<' and '{' are special there."""
    return re.sub(r"([\\<{])", r"\\\1", literal)


def form_name(e: EventDef, f: Form) -> str:
    return e.name if f.index == 0 else f"{e.name}_{f.index + 1}"


def ground_message(e: EventDef, f: Form) -> str:
    """The libevents message of one form."""
    index = {n: i + 1 for i, (n, _) in enumerate(e.wire_args(f))}
    out, literal = [], ""
    for lit, fname, spec, _ in string.Formatter().parse(f.message):
        out.append(_escape(lit))
        literal += lit
        if fname is None:
            continue
        if fname not in index:
            out.append(TEXT_MARK)
            continue
        m = _DECIMALS.fullmatch(spec or "")
        out.append(f"{{{index[fname]}:.{m.group(1)}}}" if m else f"{{{index[fname]}}}")
    if not index and not re.search(r"[A-Za-z0-9]", literal):     # nothing but free text: say what it is
        return _escape(e.doc.rstrip(".")) + (f": {TEXT_MARK}" if f.fields else "")
    return "".join(out)


def _description(e: EventDef, f: Form) -> str:
    text = e.doc
    if any(e.args[n].is_text for n, _ in f.fields):
        text += f" The text shown as {TEXT_MARK} is in the STATUSTEXT of the same event."
    if e.throttle_s is not None:
        text += f" At most one every {e.throttle_s:g} s; the others are summarised."
    return text


def events_metadata() -> dict:
    """The events metadata (libevents events.schema.json) of the whole catalogue."""
    enums = {t.name: {"type": t.base, "description": t.description,
                      "entries": {str(v): {"name": t.entry_name(v), "description": label}
                                  for v, label in sorted(t.labels.items())}} for t in ENUMS}
    events = {}
    for e in CATALOGUE:
        for f in e.forms:
            item = {"name": form_name(e, f), "message": ground_message(e, f), "description": _description(e, f)}
            args = [{"type": t.name, "name": n} for n, t in e.wire_args(f)]
            if args:
                item["arguments"] = args
            events[str(e.id * FORMS + f.index)] = item
    return {"version": METADATA_VERSION,
            "components": {str(COMPONENT_ID): {"namespace": NAMESPACE, "enums": enums,
                                               "event_groups": {"default": {"events": events}}}}}


def metadata_bytes() -> bytes:
    """The events metadata file as served: compact (a keyless station reads it at the link's
    read pace), stable bytes (its CRC goes in the general metadata)."""
    return json.dumps(events_metadata(), separators=(",", ":"), sort_keys=True, ensure_ascii=False).encode("utf-8")


def _cell(s: str) -> str:
    return s.replace("|", "\\|")


def markdown() -> str:
    """docs/events.md: the catalogue as a table, and its enums."""
    lines = [
        "# Event catalogue",
        "",
        "Generated from the event catalogue (`interfaces/event_catalogue.py`) by",
        "`python -m interfaces.event_metadata`; a test checks that this file is up to date.",
        "",
        "Each event is one STATUSTEXT (the message, at most 50 characters, its severity) and,",
        "on the ground link, one MAVLink EVENT (id `0x01000000 + id * 10 + form`, the arguments",
        "that are not text); ground stations read the EVENT's metadata from the vehicle",
        "(component metadata, `mftp://metadata/events.json`). Throttle: occurrences closer",
        "than that are held and told as one summary (`... (+N suppressed)`); `-`: every one.",
        "",
        "| id | name | source | severity | message | arguments | throttle | what it says |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for e in CATALOGUE:
        msgs = "<br>".join(f"`{_cell(m)}`" for m in e.messages)
        args = ", ".join(f"{n}: {t.name}" for n, t in e.args.items()) or "-"
        thr = "-" if e.throttle_s is None else f"{e.throttle_s:g} s"
        lines.append(f"| {e.id} | {e.name} | {e.source} | {e.severity.name} | {msgs} | {args} | {thr} | "
                     f"{_cell(e.doc)} |")
    lines += ["", "## Argument types", "",
              "Numbers travel in the EVENT as their libevents type (`uint8_t`, `uint32_t`, `int64_t`, `float`);",
              "`text` only in the STATUSTEXT; an enum as its value, shown as its label:", "",
              "| enum | type | values |", "|---|---|---|"]
    for t in ENUMS:
        values = ", ".join(f"{v} `{label}`" if label else f"{v} (nothing)" for v, label in sorted(t.labels.items()))
        lines.append(f"| {t.name} | {t.base} | {_cell(values)} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="Write docs/events.md (and the events metadata) from the catalogue.")
    ap.add_argument("--docs", type=Path, default=DOCS, help="the markdown file (default docs/events.md)")
    ap.add_argument("--check", action="store_true", help="write nothing; exit 1 if the markdown is out of date")
    ap.add_argument("--json", type=Path, help="also write the events metadata file here")
    a = ap.parse_args(argv)
    text = markdown()
    if a.check:
        if not a.docs.is_file() or a.docs.read_text(encoding="utf-8") != text:
            print(f"{a.docs} is out of date; run: python -m interfaces.event_metadata", file=sys.stderr)
            return 1
        print(f"{a.docs} is up to date")
        return 0
    a.docs.write_text(text, encoding="utf-8")
    print(f"wrote {a.docs}")
    if a.json is not None:
        a.json.write_bytes(metadata_bytes())
        print(f"wrote {a.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
