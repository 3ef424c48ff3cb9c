"""A keyless stock ground station: MAVSDK (the ``mavsdk`` 4.x package: the C++ MAVLink SDK
in-process, no mavsdk_server) connected to a vehicle, doing what a new user's ground app
does, writing what it saw as JSON. Run as its own process by tests/test_sil_mavsdk.py (so a
native hang or crash cannot take the test runner with it):

    python tests/mavsdk_station.py --url udpin://127.0.0.1:PORT --out RESULT.json --watch-s 20

Every step records its outcome (value or the MAVSDK error), so the test judges them all.
"""
from __future__ import annotations

import argparse
import json
import threading
import time
import traceback


def _err(e: BaseException) -> str:
    return f"{type(e).__name__}: {e}"


def _until(fn, timeout_s: float, every_s: float = 0.5):
    """fn()'s value once it stops raising within ``timeout_s`` (a getter whose data has not
    arrived yet raises); else re-raise its last error."""
    end = time.monotonic() + timeout_s
    while True:
        try:
            return fn()
        except Exception:
            if time.monotonic() > end:
                raise
            time.sleep(every_s)


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--url", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--watch-s", type=float, default=20.0)
    ap.add_argument("--set-param", default="F_ALT_MAX_M")
    ap.add_argument("--inject-jet", type=int, default=18)
    a = ap.parse_args()

    from mavsdk import ComponentType, Configuration, Mavsdk
    from mavsdk.plugins.component_metadata import ComponentMetadata, MetadataType
    from mavsdk.plugins.events import Events
    from mavsdk.plugins.failure import Failure, FailureType, FailureUnit
    from mavsdk.plugins.ftp import Ftp
    from mavsdk.plugins.info import Info
    from mavsdk.plugins.mavlink_direct import MavlinkDirect, MavlinkMessage
    from mavsdk.plugins.mission_raw import MissionRaw
    from mavsdk.plugins.param import Param
    from mavsdk.plugins.telemetry import Telemetry

    res: dict = {"mavsdk": __import__("mavsdk").__version__}

    def step(name, fn):
        try:
            res[name] = {"ok": fn()}
        except Exception as e:
            res[name] = {"error": _err(e)}

    sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    try:
        res["connection"] = str(sdk.add_any_connection(a.url))
        system = sdk.first_autopilot(60.0)
        res["connected"] = system is not None
        if system is None:
            return 0
        info, tel, param = Info(system), Telemetry(system), Param(system)

        # telemetry and events first, so they cover the whole contact (the events plugin
        # reads the vehicle's events metadata through component metadata by itself)
        samples, modes, current, events = [], {}, [], []
        lock = threading.Lock()

        def on_event(ev, _):
            with lock:
                events.append({"t": time.time(), "compid": ev.compid, "namespace": ev.event_namespace,
                               "name": ev.event_name, "message": ev.message, "description": ev.description,
                               "log_level": ev.log_level.name})
        events_plugin = Events(system)
        events_plugin.subscribe_events(on_event)

        def on_pv(pv, _):
            with lock:
                samples.append([time.time(), pv.position.north_m, pv.position.east_m, pv.position.down_m,
                                pv.velocity.north_m_s, pv.velocity.east_m_s, pv.velocity.down_m_s])
        tel.subscribe_position_velocity_ned(on_pv)
        direct = MavlinkDirect(system)

        def on_available(msg, _):
            f = json.loads(msg.fields_json)
            modes[int(f["custom_mode"])] = str(f["mode_name"])

        def on_current(msg, _):
            current.append(int(json.loads(msg.fields_json)["custom_mode"]))
        direct.subscribe_message("AVAILABLE_MODES", on_available)
        direct.subscribe_message("CURRENT_MODE", on_current)

        def identity():
            v, p, i = info.get_version(), info.get_product(), info.get_identification()
            return {"major": v.flight_sw_major, "minor": v.flight_sw_minor, "patch": v.flight_sw_patch,
                    "git_hash": v.flight_sw_git_hash, "vendor_id": p.vendor_id, "product_id": p.product_id,
                    "vendor_name": p.vendor_name, "product_name": p.product_name, "hardware_uid": i.hardware_uid}
        step("identity", lambda: _until(identity, 30.0))

        def request_modes():
            ack = direct.send_command(MavlinkMessage(
                "COMMAND_LONG", 0, 0, 1, 1,
                json.dumps({"target_system": 1, "target_component": 1, "command": 512, "confirmation": 0,
                            "param1": 435, "param2": 0, "param3": 0, "param4": 0, "param5": 0, "param6": 0,
                            "param7": 0})))
            end = time.monotonic() + 10.0
            while (len(modes) < 3 or not current) and time.monotonic() < end:
                time.sleep(0.2)
            return {"ack": json.loads(ack.fields_json).get("result") if ack.fields_json else None,
                    "modes": {str(k): v for k, v in modes.items()}, "current": current[-1] if current else None,
                    "flight_mode_plugin": str(tel.flight_mode())}
        step("modes", request_modes)

        def all_params():
            got = _until(param.get_all_params, 30.0)
            return {p.name: p.value for p in got.float_params} | {p.name: p.value for p in got.int_params}
        step("params", all_params)
        step("origin", lambda: (lambda o: [o.latitude_deg, o.longitude_deg, o.altitude_m])(
            _until(tel.get_gps_global_origin, 10.0)))
        step("mission", lambda: len(MissionRaw(system).download_mission()))

        def component_metadata():
            cm = ComponentMetadata(system)
            cm.request_autopilot_component()
            md = _until(lambda: cm.get_metadata(1, MetadataType.PARAMETER), 60.0)
            return json.loads(md.json_metadata)
        step("metadata", component_metadata)
        # the events metadata (the events plugin asked for it) before the station's own FTP
        # use: MAVSDK's FTP client is one queue, and a listing between two metadata downloads
        # was seen to leave the second one waiting for good
        step("events_metadata", lambda: json.loads(
            _until(lambda: ComponentMetadata(system).get_metadata(1, MetadataType.EVENTS), 60.0).json_metadata))

        def ftp_list():
            return sorted(e.name for e in Ftp(system).list_directory("metadata").entries)
        step("ftp_list", ftp_list)

        # what only a keyed station may do: both must be refused
        step("param_set", lambda: str(param.set_param_float(a.set_param, 900000.0)))
        step("inject", lambda: str(Failure(system).inject(FailureUnit.SYSTEM_MOTOR, FailureType.OFF, a.inject_jet)))

        end = time.monotonic() + a.watch_s           # keep watching, as a ground station does
        while time.monotonic() < end:
            time.sleep(0.5)
        with lock:
            res["velocity_samples"] = list(samples)
            res["events"] = list(events)
    except Exception:
        res["crash"] = traceback.format_exc()
    finally:
        with open(a.out, "w") as f:
            json.dump(res, f, indent=1, default=str)
        sdk.destroy()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
