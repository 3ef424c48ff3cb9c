"""The Rerun recording of a finished batch run (``ellipsled batch ... --rrd``).

Same entities, timelines and blueprint as the live bridge: the History rows go through
the same RerunLogger (gse/viz/logger.py), split into its truth and FSW sources.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import rerun as rr

from common.frames import wrap_pi
from common.model import Planet, load_planet
from gse.viz.blueprint import default_blueprint
from gse.viz.logger import FSW, TRUTH, RerunLogger, SOURCE_FIELDS, VehicleGlyph

BLOCK_ROWS = 1000      # rows per send_columns chunk in a file


def r_N_from_history(h_m: np.ndarray, lat_rad: np.ndarray, lon_rad: np.ndarray, t_s: np.ndarray,
                     planet: Planet) -> np.ndarray:
    """Inertial position [m] of each row (spherical planet; N and the planet frame coincide
    at t = 0 and the planet turns about N3, so inertial longitude = lon + omega t, as the
    plant defines lon_rad)."""
    rn = planet.radius_m + h_m
    lam = lon_rad + planet.omega_radps * t_s
    cl = np.cos(lat_rad)
    return rn[:, None] * np.stack([cl * np.cos(lam), cl * np.sin(lam), np.sin(lat_rad)], axis=1)


def history_blocks(history, planet: Planet) -> tuple[np.ndarray, np.ndarray, dict, dict]:
    """(k, t_s, truth columns, FSW columns) of a History, named as SOURCE_FIELDS."""
    n = history.n
    t_s = np.asarray(history["t_s"], dtype=float)
    k = np.arange(n, dtype=np.int64)

    def get(name):
        try:
            return np.asarray(history[name], dtype=float)
        except (KeyError, TypeError):
            return None

    truth = {f: get(f) for f in SOURCE_FIELDS[TRUTH] if f != "r_N"}
    fsw = {f: get(f) for f in SOURCE_FIELDS[FSW]}
    h_m, lat, lon = get("h_m"), get("lat_rad"), get("lon_rad")
    if h_m is not None and lat is not None and lon is not None:
        truth["r_N"] = r_N_from_history(h_m, lat, lon, t_s, planet)
    if fsw.get("bank_err_rad") is None and truth.get("bank_rad") is not None \
            and fsw.get("bank_ref_rad") is not None:
        d = truth["bank_rad"] - fsw["bank_ref_rad"]
        fsw["bank_err_rad"] = np.array([wrap_pi(x) if math.isfinite(x) else math.nan for x in d])
    return k, t_s, {a: v for a, v in truth.items() if v is not None}, {a: v for a, v in fsw.items() if v is not None}


def record_history(history, events: list, path: Path, blueprint: bool = True, *,
                   planet: Planet | None = None, glyph: VehicleGlyph | None = None) -> Path:
    """Write ``history`` (ellipsled/sil/history.py History) and ``events`` (common.events.Event
    list) to the .rrd ``path``; returns the path. The planet (default Mars) places the
    trajectory; ``glyph`` draws the vehicle (default data/vehicles/ellipsled.toml)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    planet = planet or load_planet("mars")
    rec = rr.RecordingStream("ellipsled", recording_id=f"batch-{path.stem}")
    bp = default_blueprint() if blueprint else None
    rec.set_sinks(rr.FileSink(path), default_blueprint=bp)
    rec.send_recording_name(path.stem)
    log = RerunLogger(rec, flush_rows=BLOCK_ROWS, flush_s=math.inf, glyph=glyph, radius_m=planet.radius_m)
    k, t_s, truth, fsw = history_blocks(history, planet)
    log.log_block(TRUTH, k, t_s, truth)
    log.log_block(FSW, k, t_s, fsw)
    for ev in events or []:
        t = getattr(ev, "t_s", math.nan)
        kk = int(np.clip(np.searchsorted(t_s, t, side="right") - 1, 0, max(len(t_s) - 1, 0))) \
            if len(t_s) and isinstance(t, (int, float)) and math.isfinite(t) else None
        log.log_event(ev, k=kk)
    log.close()
    rec.flush()
    rec.disconnect()        # finalises the file (footer)
    return path
