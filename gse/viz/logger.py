"""RerunLogger: truth and FSW rows -> Rerun entities, batched with ``send_columns``.

Plain code: no transport, no threads. Rows are copied into preallocated per-source
buffers (``truth`` from the plant, ``fsw`` from the flight software) and sent column-wise
when ``flush_rows`` rows are buffered or ``flush_s`` seconds have passed since the last
send (docs/interfaces/index.md: batch with ``send_columns``, never one ``rr.log`` per signal
per frame). Every entity carries the two timelines ``step`` (sequence, control step k) and
``sim_time`` (duration, simulated time).

Bad input never crashes the logger: a field that is missing or cannot be converted is
NaN for that row (counted in ``stats['bad_values']``); rows whose values are not all
finite are left out of the affected entity only (counted in ``stats['skipped_rows']``);
an SDK error while sending is counted in ``stats['send_errors']``.

Angles are shown in degrees, altitude in km (entity names carry the unit).

The map (``map/``): the ground track (longitude, latitude in degrees; x east, y north, z up)
decimated to every MAP_EVERY-th control step, the deploy target, and the predicted deploy
point of each predictor-corrector answer, logged once per answer (guidance rate, 0.5-1 Hz)
with its great-circle miss (``guidance/predicted_miss_km``), never at the control rate.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Callable, Mapping

import numpy as np
import rerun as rr

from common.config import load_toml, resolve
from common.model import load_planet, load_vehicle
from common.mrp import sigma_to_quat
from interfaces.event_catalogue import BY_NAME
from interfaces.event_metadata import markdown as event_catalogue_markdown
from interfaces.records import FSW_STATE, GUID_PREDICTION, GUID_TARGET, field_shapes
from interfaces.vocabulary import HEALTH_NAMES, N_JETS, Mode, Severity

DEG = 180.0 / math.pi
TRUTH, FSW = "truth", "fsw"

# Buffered fields per source: name -> trailing shape. The plant's: names as
# ellipsled/sil/history.py TRUTH_FIELDS, plus r_N [m] for the 3D view. The FSW's: every field
# of its output record (interfaces/records.py FSW_STATE) but the step and time, which every
# row carries as its timelines.
SOURCE_FIELDS: dict[str, dict[str, tuple[int, ...]]] = {
    TRUTH: {"bank_rad": (), "alpha_rad": (), "beta_rad": (), "omega_BN_B": (3,), "sigma_BN": (3,),
            "r_N": (3,), "h_m": (), "V_rel_mps": (), "gamma_rad": (), "mach": (), "qbar_pa": (),
            "decel_g": (), "tau_jets_B": (3,), "lat_rad": (), "lon_rad": ()},
    FSW: {n: shp for n, shp in field_shapes(FSW_STATE).items() if n not in ("k", "t_ns")},
}
MAP_EVERY = 10             # ground-track points: every 10th control step (5 Hz at 50 Hz)

# Rerun TextLog levels of the MAVLink severities.
TEXTLOG_LEVEL = {Severity.EMERGENCY: "CRITICAL", Severity.ALERT: "CRITICAL", Severity.CRITICAL: "CRITICAL",
                 Severity.ERROR: "ERROR", Severity.WARNING: "WARN", Severity.NOTICE: "INFO",
                 Severity.INFO: "INFO", Severity.DEBUG: "DEBUG"}

# The events table (entity "events", beside the TextLog): one row per event, the columns its
# catalogue entry's fields (interfaces/event_catalogue.py; 0 / "" for a code it does not know).
# The catalogue itself is the markdown document "event_catalogue" (the table of docs/events.md).
EVENT_COLUMNS = ("event_id", "event_name", "source", "severity")

JET_NAMES = [f"J{j + 1}" for j in range(N_JETS)]
LANE_HIGH = 0.8     # jets/lanes: lane j+1 reads j+1 when off, j+1+LANE_HIGH when firing


@dataclass(frozen=True)
class Channel:
    """One time-series entity: ``value(block) -> (n, m)`` from one source's field."""
    entity: str
    source: str
    field: str
    index: int | None = None          # component of a vector field; None = whole field
    scale: float = 1.0
    names: tuple[str, ...] | None = None


def _scalar_channels() -> list[Channel]:
    ch = [
        Channel("bank/actual_deg", TRUTH, "bank_rad", scale=DEG),
        Channel("bank/reference_deg", FSW, "bank_ref_rad", scale=DEG),
        Channel("bank/error_deg", FSW, "bank_err_rad", scale=DEG),
        Channel("aero/alpha_deg", TRUTH, "alpha_rad", scale=DEG),
        Channel("aero/beta_deg", TRUTH, "beta_rad", scale=DEG),
        Channel("rates/omega_BN_B_degps", TRUTH, "omega_BN_B", scale=DEG, names=("p", "q", "r")),
        Channel("adapt/theta_hat", FSW, "theta_hat", names=tuple(f"theta{i + 1}" for i in range(9))),
        Channel("entry/altitude_km", TRUTH, "h_m", scale=1e-3),
        Channel("entry/speed_mps", TRUTH, "V_rel_mps"),
        Channel("entry/gamma_deg", TRUTH, "gamma_rad", scale=DEG),
        Channel("entry/mach", TRUTH, "mach"),
        Channel("entry/qbar_pa", TRUTH, "qbar_pa"),
        Channel("entry/decel_g", TRUTH, "decel_g"),
        Channel("timing/compute_us", FSW, "compute_us"),
        Channel("timing/alloc_us", FSW, "alloc_us"),
        Channel("timing/jitter_us", FSW, "jitter_us"),
        Channel("timing/slips", FSW, "slips"),
        Channel("fsw/alloc_degraded", FSW, "alloc_degraded"),
    ]
    for i, a in enumerate("xyz"):
        ch += [Channel(f"torque/{a}/commanded_Nm", FSW, "u_cal_B", index=i),
               Channel(f"torque/{a}/allocated_Nm", FSW, "tau_alloc_B", index=i),
               Channel(f"torque/{a}/applied_Nm", TRUTH, "tau_jets_B", index=i)]
    return ch


SCALAR_CHANNELS = _scalar_channels()


# --------------------------------------------------------------------------- vehicle glyph
@dataclass(frozen=True)
class VehicleGlyph:
    """What the 3D views draw: the body box and one arrow per jet, in body axes [m]."""
    half_sizes_B_m: np.ndarray      # (3,)
    jet_origin_B_m: np.ndarray      # (18, 3)
    jet_vector_B_m: np.ndarray      # (18, 3)


def glyph_from_vehicle(name_or_path: str = "ellipsled") -> VehicleGlyph:
    """Box length_m x diameter_m x diameter_m (long axis = body x) from the vehicle file.

    Jets given by geometry are drawn as plumes (arrow -F from the point of the line of
    action nearest the centre of mass, F x T / |F|^2, since T = r x F); jets given by the
    paper's torque matrix only have no position: each is drawn from the centre along the
    torque it produces, scaled to the largest jet torque.
    """
    veh = load_vehicle(name_or_path)
    raw = load_toml(resolve("vehicles", name_or_path)).get("vehicle", {})
    length_m = float(raw.get("length_m", 2.0 * veh.l_ref_m))
    diameter_m = float(raw.get("diameter_m", veh.l_ref_m))
    half = np.array([length_m, diameter_m, diameter_m]) / 2.0
    T = np.asarray(veh.torque_matrix_Nm, dtype=float).T         # (18, 3)
    if veh.jet_force_B_N is not None:
        F = np.asarray(veh.jet_force_B_N, dtype=float).T         # (18, 3)
        F2 = np.maximum(np.sum(F * F, axis=1, keepdims=True), 1e-12)
        origin = np.cross(F, T) / F2
        vector = -F / np.sqrt(F2)
    else:
        origin = np.zeros((N_JETS, 3))
        vector = T / max(float(np.max(np.linalg.norm(T, axis=1))), 1e-12) * half[0]
    return VehicleGlyph(half, origin, vector)


# --------------------------------------------------------------------------- logger
class _Buffer:
    """Preallocated rows of one source (float64; NaN = not provided)."""

    def __init__(self, fields: dict[str, tuple[int, ...]], capacity: int):
        self.fields = fields
        self.capacity = capacity
        self.k = np.zeros(capacity, dtype=np.int64)
        self.t_s = np.zeros(capacity)
        self.a = {f: np.full((capacity,) + shp, np.nan) for f, shp in fields.items()}
        self.n = 0


def _time_columns(k: np.ndarray, t_s: np.ndarray) -> list[rr.TimeColumn]:
    t_ns = np.rint(t_s * 1e9).astype(np.int64).astype("timedelta64[ns]")
    return [rr.TimeColumn("step", sequence=k), rr.TimeColumn("sim_time", duration=t_ns)]


class RerunLogger:
    """Logs truth / FSW rows and events to one RecordingStream (``rec=None``: logs nothing).

    ``flush_rows``: send every this many buffered rows of a source; ``flush_s``: or when
    this much wall time (``clock``) has passed since the last send (checked at each call);
    ``math.inf`` disables the timer (batch files). ``glyph``: vehicle drawing (default
    from data/vehicles/ellipsled.toml). ``vis_scale``: the vehicle glyph in the km-scaled
    trajectory view is drawn this many times its size. ``radius_m``: the planet's, for the
    predicted miss (default data/planets/mars.toml).
    """

    def __init__(self, rec: rr.RecordingStream | None, *, flush_rows: int = 50, flush_s: float = 1.0,
                 glyph: VehicleGlyph | None = None, vis_scale: float = 2000.0,
                 clock: Callable[[], float] = time.monotonic, radius_m: float | None = None):
        if not isinstance(flush_rows, int) or flush_rows < 1:
            raise ValueError(f"RerunLogger: flush_rows must be an int >= 1, got {flush_rows!r}")
        if not flush_s > 0:
            raise ValueError(f"RerunLogger: flush_s must be > 0, got {flush_s!r}")
        self.rec = rec
        self.flush_rows = flush_rows
        self.flush_s = float(flush_s)
        self.clock = clock
        self.glyph = glyph if glyph is not None else glyph_from_vehicle()
        self.vis_scale = float(vis_scale)
        self.radius_m = float(radius_m) if radius_m is not None else load_planet("mars").radius_m
        self._buf = {src: _Buffer(f, flush_rows) for src, f in SOURCE_FIELDS.items()}
        self._events: list[tuple] = []           # (k, t_s, text, level, *EVENT_COLUMNS)
        self._last_flush = clock()
        self._last_health: np.ndarray | None = None
        self._last_mode: float | None = None
        self._last_r_km: np.ndarray | None = None
        self._last_track: np.ndarray | None = None     # last ground-track point (lon, lat, 0) [deg]
        self._last_cycles: float | None = None         # guid_cycles of the last predicted point logged
        self._last_target: tuple | None = None
        self._last_k, self._last_t, self._dt_est = 0, 0.0, None
        self.stats = {"rows_truth": 0, "rows_fsw": 0, "events": 0, "send_columns": 0, "log": 0,
                      "flushes": 0, "bad_values": 0, "skipped_rows": 0, "send_errors": 0}
        if rec is not None:
            self._log_static()

    @property
    def enabled(self) -> bool:
        return self.rec is not None

    # ------------------------------------------------------------------ input
    def log_truth(self, k: int, t_s: float, row) -> None:
        """One plant row (mapping or structured record with SOURCE_FIELDS['truth'] names)."""
        self._log_row(TRUTH, k, t_s, row)

    def log_fsw(self, k: int, t_s: float, row) -> None:
        """One FSW row (mapping or structured record with SOURCE_FIELDS['fsw'] names)."""
        self._log_row(FSW, k, t_s, row)

    def log_block(self, source: str, k: np.ndarray, t_s: np.ndarray, cols: Mapping[str, np.ndarray]) -> None:
        """Many rows at once: ``cols[name]`` has shape (n, *field shape); missing names are NaN."""
        if source not in self._buf:
            raise ValueError(f"log_block: source must be one of {tuple(self._buf)}, got {source!r}")
        if self.rec is None:
            return
        k = np.asarray(k, dtype=np.int64).reshape(-1)
        t_s = np.asarray(t_s, dtype=float).reshape(-1)
        n = len(k)
        if len(t_s) != n:
            raise ValueError(f"log_block: k has {n} rows, t_s has {len(t_s)}")
        b = self._buf[source]
        arrays = {}
        for name, shp in b.fields.items():
            if name not in cols:
                continue
            try:
                v = np.asarray(cols[name], dtype=float).reshape((n,) + shp)
            except (TypeError, ValueError):
                self.stats["bad_values"] += n
                continue
            arrays[name] = v
        i = 0
        while i < n:
            m = min(n - i, b.capacity - b.n)
            sl = slice(b.n, b.n + m)
            b.k[sl], b.t_s[sl] = k[i:i + m], t_s[i:i + m]
            for name, arr in b.a.items():
                arr[sl] = arrays[name][i:i + m] if name in arrays else np.nan
            b.n += m
            i += m
            self.stats[f"rows_{source}"] += m
            if b.n >= b.capacity:
                self._flush_source(source)
        if n:
            self._note_time(int(k[-1]), float(t_s[-1]))
        self._maybe_flush_on_time()

    def log_event(self, event, k: int | None = None) -> None:
        """A common.events.Event (t_s, severity, source, code, text) as a TextLog at its time.
        ``k``: its step; by default the step nearest its time from the rows seen so far."""
        if self.rec is None:
            return
        try:
            t_s = float(event.t_s)
            if not math.isfinite(t_s):
                raise ValueError("non-finite event time")
            try:
                severity = Severity(int(event.severity))
            except ValueError:
                severity = Severity.INFO
            level = TEXTLOG_LEVEL[severity]
            text = f"[{event.source}] {event.code}: {event.text}"
            entry = BY_NAME.get(event.code)
            row = (entry.id if entry else 0, event.code, str(event.source), severity.name)
        except Exception:
            self.stats["bad_values"] += 1
            return
        if k is None:
            k = self._last_k
            if self._dt_est:
                k = max(0, self._last_k + int(round((t_s - self._last_t) / self._dt_est)))
        self._events.append((int(k), t_s, text, level, *row))
        self.stats["events"] += 1
        if len(self._events) >= self.flush_rows:
            self._flush_events()

    def tick(self) -> None:
        """Send what is buffered if ``flush_s`` has passed (call it when idle)."""
        if self.rec is not None:
            self._maybe_flush_on_time()

    def flush(self) -> None:
        """Send everything buffered now."""
        if self.rec is None:
            return
        for src in self._buf:
            self._flush_source(src)
        self._flush_events()
        self._last_flush = self.clock()

    def close(self) -> None:
        """Flush, then flush the recording stream (files get their data written)."""
        if self.rec is None:
            return
        self.flush()
        try:
            self.rec.flush()
        except Exception:
            self.stats["send_errors"] += 1

    # ------------------------------------------------------------------ internals
    def _log_row(self, source: str, k: int, t_s: float, row) -> None:
        if self.rec is None:
            return
        b = self._buf[source]
        i = b.n
        try:
            b.k[i], b.t_s[i] = int(k), float(t_s)
        except (TypeError, ValueError, OverflowError):
            self.stats["bad_values"] += 1
            return
        for name, arr in b.a.items():
            try:
                arr[i] = row[name]
            except (KeyError, IndexError, ValueError, TypeError):
                arr[i] = np.nan
                if _has(row, name):
                    self.stats["bad_values"] += 1
        b.n += 1
        self.stats[f"rows_{source}"] += 1
        self._note_time(int(b.k[i]), float(b.t_s[i]))
        if b.n >= b.capacity:
            self._flush_source(source)
        self._maybe_flush_on_time()

    def _note_time(self, k: int, t_s: float) -> None:
        if k > self._last_k and math.isfinite(t_s):
            dt = (t_s - self._last_t) / (k - self._last_k)
            if dt > 0:
                self._dt_est = dt
        if math.isfinite(t_s):
            self._last_k, self._last_t = k, t_s

    def _maybe_flush_on_time(self) -> None:
        if self.flush_s != math.inf and self.clock() - self._last_flush >= self.flush_s:
            self.flush()

    def _send(self, entity: str, index: list, columns) -> None:
        try:
            self.rec.send_columns(entity, indexes=index, columns=columns)
            self.stats["send_columns"] += 1
        except Exception:
            self.stats["send_errors"] += 1

    def _log(self, entity: str, archetype, static: bool = False) -> None:
        try:
            self.rec.log(entity, archetype, static=static)
            self.stats["log"] += 1
        except Exception:
            self.stats["send_errors"] += 1

    def _log_static(self) -> None:
        for c in SCALAR_CHANNELS:
            if c.names is not None:
                self._log(c.entity, rr.SeriesLines(names=list(c.names)), static=True)
        self._log("jets/lanes", rr.SeriesLines(names=JET_NAMES), static=True)
        g = self.glyph
        km = 1e-3 * self.vis_scale
        self._log("world/vehicle/body", rr.Boxes3D(half_sizes=[g.half_sizes_B_m * km], colors=[(200, 200, 210)],
                                                    fill_mode=rr.components.FillMode.Solid), static=True)
        self._log("attitude/body/box", rr.Boxes3D(half_sizes=[g.half_sizes_B_m], colors=[(200, 200, 210)],
                                                   fill_mode=rr.components.FillMode.Solid), static=True)
        self._log("attitude/reference/box", rr.Boxes3D(half_sizes=[g.half_sizes_B_m * 1.05], colors=[(80, 220, 80)],
                                                        fill_mode=rr.components.FillMode.MajorWireframe), static=True)
        L = 1.5 * float(g.half_sizes_B_m[0])
        self._log("attitude/N", rr.Arrows3D(origins=np.zeros((3, 3)), vectors=np.eye(3) * L,
                                            colors=[(255, 80, 80), (80, 255, 80), (80, 80, 255)],
                                            labels=["N1", "N2", "N3"]), static=True)
        self._log("map", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)     # x east (lon), y north (lat)
        self._log("event_catalogue", rr.TextDocument(event_catalogue_markdown(), media_type=rr.MediaType.MARKDOWN),
                  static=True)

    def _flush_source(self, source: str) -> None:
        b = self._buf[source]
        n = b.n
        if n == 0 or self.rec is None:
            return
        b.n = 0
        self.stats["flushes"] += 1
        k, t_s = b.k[:n].copy(), b.t_s[:n].copy()
        ok_t = np.isfinite(t_s)
        if not ok_t.all():
            self.stats["skipped_rows"] += int(np.count_nonzero(~ok_t))
        idx_all = _time_columns(k[ok_t], t_s[ok_t])
        a = {name: arr[:n][ok_t] for name, arr in b.a.items()}
        k, t_s = k[ok_t], t_s[ok_t]
        if len(k) == 0:
            return

        def index_for(mask: np.ndarray) -> list:
            return idx_all if mask.all() else _time_columns(k[mask], t_s[mask])

        for c in SCALAR_CHANNELS:
            if c.source != source:
                continue
            v = a[c.field] if c.index is None else a[c.field][:, c.index]
            v = v.reshape(len(k), -1) * c.scale
            mask = np.isfinite(v).all(axis=1)
            if not mask.any():
                continue                       # field not provided in this block
            self.stats["skipped_rows"] += int(np.count_nonzero(~mask))
            self._send(c.entity, index_for(mask), rr.Scalars.columns(scalars=v[mask]))
        if source == TRUTH:
            self._flush_truth_3d(a, index_for)
            self._flush_track(a, k, t_s)
        else:
            self._flush_guidance_map(a, k, t_s)
            self._flush_fsw_special(a, k, t_s, index_for)
        for arr in b.a.values():
            arr[:n] = np.nan

    def _flush_truth_3d(self, a: dict, index_for) -> None:
        sig, r = a["sigma_BN"], a["r_N"]
        m_att = np.isfinite(sig).all(axis=1) & (np.sum(sig * sig, axis=1) < 1e6)
        if m_att.any():
            q_xyzw = _quat_xyzw(sig[m_att])
            self._send("attitude/body", index_for(m_att), rr.Transform3D.columns(quaternion=q_xyzw))
            m_pos = m_att & np.isfinite(r).all(axis=1)
            if m_pos.any():
                r_km = r[m_pos] * 1e-3
                q = _quat_xyzw(sig[m_pos])
                self._send("world/vehicle", index_for(m_pos), rr.Transform3D.columns(translation=r_km, quaternion=q))
                prev = np.vstack([self._last_r_km if self._last_r_km is not None else r_km[:1], r_km[:-1]])
                strips = np.stack([prev, r_km], axis=1)          # (n, 2, 3): segment per step
                self._send("world/trajectory", index_for(m_pos), rr.LineStrips3D.columns(strips=strips))
                self._last_r_km = r_km[-1].copy()

    def _flush_track(self, a: dict, k: np.ndarray, t_s: np.ndarray) -> None:
        """Ground track: one segment per MAP_EVERY steps, from the last point logged."""
        lat, lon = a["lat_rad"], a["lon_rad"]
        m = np.isfinite(lat) & np.isfinite(lon) & (k % MAP_EVERY == 0)
        if not m.any():
            return
        pts = np.stack([np.degrees(lon[m]), np.degrees(lat[m]), np.zeros(int(m.sum()))], axis=1)
        prev = np.vstack([self._last_track if self._last_track is not None else pts[:1], pts[:-1]])
        wrap = np.abs(pts[:, 0] - prev[:, 0]) > 180.0          # across the antimeridian: no segment
        prev[wrap] = pts[wrap]
        self._send("map/track", _time_columns(k[m], t_s[m]),
                   rr.LineStrips3D.columns(strips=np.stack([prev, pts], axis=1)))
        self._last_track = pts[-1].copy()

    def _flush_guidance_map(self, a: dict, k: np.ndarray, t_s: np.ndarray) -> None:
        """The target when it changes; the predicted deploy point once per guidance answer."""
        flags = np.nan_to_num(a["guid_flags"]).astype(np.int64)
        rows = np.nonzero(flags & GUID_TARGET)[0]
        if len(rows):
            i = rows[-1]
            tgt = (float(a["target_lon_rad"][i]), float(a["target_lat_rad"][i]))
            if tgt != self._last_target and all(map(math.isfinite, tgt)):
                self._last_target = tgt
                self._at(int(k[i]), float(t_s[i]))
                self._log("map/target", rr.Points3D([[math.degrees(tgt[0]), math.degrees(tgt[1]), 0.0]],
                                                    labels=["target"], colors=[(255, 60, 60)],
                                                    radii=rr.Radius.ui_points(7.0)))
        rows = np.nonzero(flags & GUID_PREDICTION)[0]
        cyc, plat, plon = a["guid_cycles"][rows], a["pred_lat_rad"][rows], a["pred_lon_rad"][rows]
        ok = np.isfinite(cyc) & np.isfinite(plat) & np.isfinite(plon)
        rows, cyc, plat, plon = rows[ok], cyc[ok], plat[ok], plon[ok]
        if not len(rows):
            return
        last = self._last_cycles if self._last_cycles is not None else -1.0
        new = np.diff(np.concatenate(([last], cyc))) != 0         # a new answer at these rows
        if not new.any():
            return
        self._last_cycles = float(cyc[-1])
        ni, plat, plon = rows[new], plat[new], plon[new]
        pts = np.stack([np.degrees(plon), np.degrees(plat), np.zeros(len(ni))], axis=1)
        idx = _time_columns(k[ni], t_s[ni])
        self._send("map/predicted", idx, rr.Points3D.columns(positions=pts, radii=np.full(len(ni), -4.0),
                                                             colors=np.tile([255, 200, 0], (len(ni), 1))))
        if self._last_target is not None:
            tlon, tlat = self._last_target
            miss = [_great_circle_m(la, lo, tlat, tlon, self.radius_m) * 1e-3 for la, lo in zip(plat, plon)]
            self._send("guidance/predicted_miss_km", idx, rr.Scalars.columns(scalars=np.array(miss)))

    def _at(self, k: int, t_s: float) -> None:
        try:
            self.rec.set_time("step", sequence=k)
            self.rec.set_time("sim_time", duration=np.timedelta64(int(round(t_s * 1e9)), "ns"))
        except Exception:
            self.stats["send_errors"] += 1

    def _flush_fsw_special(self, a: dict, k: np.ndarray, t_s: np.ndarray, index_for) -> None:
        jets = a["jets_cmd"]
        m = np.isfinite(jets).all(axis=1)
        if m.any():
            on = jets[m] > 0.5
            lanes = np.arange(1, N_JETS + 1)[None, :] + LANE_HIGH * on
            idx = index_for(m)
            self._send("jets/lanes", idx, rr.Scalars.columns(scalars=lanes))
            self._send("jets/n_firing", idx, rr.Scalars.columns(scalars=on.sum(axis=1).astype(float)))
            g = self.glyph
            rows, cols = np.nonzero(on)
            lengths = np.bincount(rows, minlength=len(on))
            self._send("attitude/body/jets", idx,
                       rr.Arrows3D.columns(origins=g.jet_origin_B_m[cols], vectors=g.jet_vector_B_m[cols],
                                           labels=[JET_NAMES[c] for c in cols]).partition(lengths))
        sig = a["sigma_RN"]
        m = np.isfinite(sig).all(axis=1) & (np.sum(sig * sig, axis=1) < 1e6)
        if m.any():
            self._send("attitude/reference", index_for(m), rr.Transform3D.columns(quaternion=_quat_xyzw(sig[m])))
        # health and mode: logged when they change (state lanes + current-health bar chart)
        h = a["health"]
        m = np.isfinite(h).all(axis=1)
        changed = []
        for i in np.nonzero(m)[0]:
            if self._last_health is None or not np.array_equal(h[i], self._last_health):
                changed.append(i)
                self._last_health = h[i].copy()
        if changed:
            ci = np.array(changed)
            codes = h[ci].astype(int)
            names = [HEALTH_NAMES.get(int(c), f"code{int(c)}") for c in codes.ravel()]
            self._send("jets/health", _time_columns(k[ci], t_s[ci]),
                       rr.StateChange.columns(state=names).partition(np.full(len(ci), N_JETS)))
            for i, c in zip(ci, codes):      # rare (a fault): one bar chart per change
                self._at(int(k[i]), float(t_s[i]))
                self._log("jets/health_code", rr.BarChart(c.astype(float)))
        mode = a["mode"]
        changed = []
        for i in np.nonzero(np.isfinite(mode))[0]:
            if self._last_mode is None or mode[i] != self._last_mode:
                changed.append(i)
                self._last_mode = float(mode[i])
        if changed:
            ci = np.array(changed)
            names = [_mode_name(v) for v in mode[ci]]
            self._send("fsw/mode", _time_columns(k[ci], t_s[ci]), rr.StateChange.columns(state=names))

    def _flush_events(self) -> None:
        if not self._events or self.rec is None:
            return
        ev, self._events = self._events, []
        k = np.array([e[0] for e in ev], dtype=np.int64)
        t = np.array([e[1] for e in ev])
        table = {name: [e[4 + i] for e in ev] for i, name in enumerate(EVENT_COLUMNS)}
        self._send("events", _time_columns(k, t),
                   [*rr.TextLog.columns(text=[e[2] for e in ev], level=[e[3] for e in ev]),
                    *rr.AnyValues.columns(**table)])


def _great_circle_m(lat1: float, lon1: float, lat2: float, lon2: float, radius_m: float) -> float:
    """Haversine distance [m] on a sphere of radius_m."""
    a = math.sin((lat2 - lat1) / 2) ** 2 + math.cos(lat1) * math.cos(lat2) * math.sin((lon2 - lon1) / 2) ** 2
    return 2.0 * radius_m * math.asin(min(1.0, math.sqrt(a)))


def _has(row, name: str) -> bool:
    try:
        names = row.dtype.names if hasattr(row, "dtype") else row.keys()
        return name in names
    except Exception:
        return False


def _mode_name(v: float) -> str:
    try:
        return Mode(int(v)).name
    except ValueError:
        return f"mode{int(v)}"


def _quat_xyzw(sigma: np.ndarray) -> np.ndarray:
    """Rerun quaternions (x, y, z, w) of MRP rows; sigma_to_quat gives scalar-first.
    The Euler parameters of sigma_BN rotate body-axis vectors into N, as Rerun's
    child-to-parent transform expects."""
    q = np.array([sigma_to_quat(s) for s in sigma]).reshape(-1, 4)
    return np.concatenate([q[:, 1:], q[:, :1]], axis=1)

