"""Component metadata a ground station can show (MAVLink component metadata protocol):
the general metadata file, the parameter metadata file, built once at start from the
parameter registry's own declarations (``ParamRegistry.describe()``, the source of
`ellipsled params --json` and of the README table), and the events metadata file, the
event catalogue's (interfaces/event_metadata.py: what the EVENT messages mean), served
read-only over MAVLink FTP (ftp.py) and announced by COMPONENT_METADATA.

Only ground-settable parameters are listed: they are the ones a ground station sees over
the parameter protocol, by their MAVLink ids. Every value goes on the wire as REAL32, so
the type is "Float" for all of them (integers carry decimalPlaces 0 and increment 1).
"""
from __future__ import annotations

import json
import zlib
from importlib import metadata

from interfaces import event_metadata
from interfaces.mavlink import dialect as mav

METADATA_DIR = "metadata"
GENERAL_PATH = f"{METADATA_DIR}/general.json"
PARAMETER_PATH = f"{METADATA_DIR}/parameters.json"
EVENTS_PATH = f"{METADATA_DIR}/events.json"
PARAMETER_FORMAT_VERSION = 3           # parameter.schema.json: version >= 3
GENERAL_FORMAT_VERSION = 1


def mftp_uri(path: str) -> str:
    """MAVLink FTP URI of a file on this component."""
    return f"mftp://{path}"


def crc32(data: bytes) -> int:
    """The CRC32 MAVLink FTP's CalcFileCRC32 and the metadata's fileCrc use (zlib's)."""
    return zlib.crc32(data) & 0xFFFFFFFF


def _dump(obj) -> bytes:
    return json.dumps(obj, indent=1, sort_keys=True).encode("utf-8")


def parameter_entries(registry) -> list[dict]:
    """parameter.schema.json items for every ground-settable parameter."""
    out = []
    for r in registry.describe():
        if not r["ground_settable"]:
            continue
        item = {"name": r["param_id"], "type": "Float", "shortDesc": r["name"], "longDesc": r["description"],
                "group": r["owner"], "default": float(r["default"]), "rebootRequired": False}
        if r["unit"] not in ("", "-"):
            item["units"] = r["unit"]
        if r["min"] is not None:
            item["min"] = float(r["min"])
        if r["max"] is not None:
            item["max"] = float(r["max"])
        if r["integer"]:
            item["decimalPlaces"] = 0
            item["increment"] = 1
        out.append(item)
    return out


def firmware_version() -> str:
    """major.minor.patch of the installed package ("0.0.0" when not installed)."""
    try:
        parts = metadata.version("ellipsled").split(".")[:3]
    except metadata.PackageNotFoundError:
        return "0.0.0"
    parts = [p if p.isdigit() else "0" for p in parts] + ["0"] * (3 - len(parts))
    return ".".join(parts[:3])


def build(registry, model_name: str) -> dict[str, bytes]:
    """{path: file content}: the parameter and events metadata, then the general metadata
    naming them (with their CRCs, so a ground station can cache them)."""
    params = _dump({"version": PARAMETER_FORMAT_VERSION, "parameters": parameter_entries(registry)})
    events = event_metadata.metadata_bytes()
    general = _dump({"version": GENERAL_FORMAT_VERSION, "vendorName": "ellipsled", "modelName": model_name,
                     "firmwareVersion": firmware_version(),
                     "metadataTypes": [{"type": mav.COMP_METADATA_TYPE_PARAMETER, "uri": mftp_uri(PARAMETER_PATH),
                                        "fileCrc": crc32(params)},
                                       {"type": mav.COMP_METADATA_TYPE_EVENTS, "uri": mftp_uri(EVENTS_PATH),
                                        "fileCrc": crc32(events)}]})
    return {GENERAL_PATH: general, PARAMETER_PATH: params, EVENTS_PATH: events}
