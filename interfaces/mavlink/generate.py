"""Generate the Python bindings of the ellipsled MAVLink dialect with pymavlink's mavgen.

    python -m interfaces.mavlink.generate            # rewrite generated/ellipsled.py
    python -m interfaces.mavlink.generate --check    # exit 1 if it is out of date

The dialect XML includes ``common.xml``; mavgen resolves includes relative to the XML's
folder, so generation copies our XML next to the XML files shipped with the installed
pymavlink (``pymavlink/dialects/v20``) in a temporary folder. Nothing is fetched: it
works offline. The output carries no timestamp or path, so it is reproducible and the
committed copy is checked by ``tests/test_mavlink_dialect.py``.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import re
import shutil
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
DIALECT_XML = HERE / "ellipsled.xml"
GENERATED_PY = HERE / "generated" / "ellipsled.py"

_INCLUDE_RE = re.compile(r"<include>\s*([^<\s]+)\s*</include>")


class GenerationError(RuntimeError):
    pass


def pymavlink_xml_dir() -> Path:
    """Folder of the MAVLink 2 XML definitions shipped with the installed pymavlink."""
    import pymavlink
    return Path(pymavlink.__file__).resolve().parent / "dialects" / "v20"


def _copy_with_includes(xml: Path, src_dir: Path, dst_dir: Path, seen: set[str]) -> None:
    for name in _INCLUDE_RE.findall(xml.read_text(encoding="utf-8")):
        if name in seen:
            continue
        seen.add(name)
        src = src_dir / name
        if not src.is_file():
            raise GenerationError(f"{xml.name}: included file {name!r} not found in {src_dir}")
        shutil.copyfile(src, dst_dir / name)
        _copy_with_includes(src, src_dir, dst_dir, seen)


def generate_source(xml_path: Path = DIALECT_XML) -> str:
    """Run mavgen (wire protocol 2.0, Python3, XSD validation on) and return the module text."""
    from pymavlink.generator import mavgen, mavparse

    with tempfile.TemporaryDirectory(prefix="ellipsled-mavgen-") as tmp:
        tmp_dir = Path(tmp)
        xml_copy = tmp_dir / xml_path.name
        shutil.copyfile(xml_path, xml_copy)
        _copy_with_includes(xml_copy, pymavlink_xml_dir(), tmp_dir, set())
        out_py = tmp_dir / (xml_path.stem + ".py")
        opts = mavgen.Opts(str(out_py), wire_protocol=mavparse.PROTOCOL_2_0,
                           language="Python3", validate=True)
        log = io.StringIO()
        try:
            with contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
                ok = mavgen.mavgen(opts, [str(xml_copy)])
        except SystemExit:    # mavgen calls exit() on some XML errors
            ok = False
        if not ok or not out_py.is_file():
            raise GenerationError(f"mavgen failed on {xml_path}:\n{log.getvalue()}")
        return out_py.read_text(encoding="utf-8")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true",
                    help="do not write; exit 1 if the committed bindings differ from the XML")
    ap.add_argument("--out", type=Path, default=GENERATED_PY, help="output .py file")
    args = ap.parse_args(argv)
    try:
        text = generate_source()
    except GenerationError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if args.check:
        current = args.out.read_text(encoding="utf-8") if args.out.is_file() else None
        if current != text:
            print(f"{args.out} is out of date; run: python -m interfaces.mavlink.generate",
                  file=sys.stderr)
            return 1
        print(f"{args.out} is up to date")
        return 0
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text, encoding="utf-8")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
