"""A Monte Carlo campaign: its data file, the per-run draw, and the dispersed scenario.

Spec docs/scenarios.md (Monte Carlo campaign). A run's noise seed and dispersions are a pure
function of (master seed, run_id): ``draw_run`` never depends on other runs, on the order
runs finish, or on the machine, so a campaign can be resumed, extended or spread over a
cluster, and any run is rebuilt from its record by ``apply_dispersion``.
"""
from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from common.config import ConfigError, Table, load_toml, resolve
from common.model import INERTIA_KEYS, FaultEvent, fsw_overrides, Scenario, Truth, inertia_matrix, inertia_vector
from interfaces.vocabulary import N_JETS

AERO_KEYS = ("C_lbeta", "C_malpha", "C_nbeta")
BROKEN_FDIR_DELAY_S = -1.0   # outside fdir.delay_s's bounds: the FSW refuses it, run() raises


# a campaign of a million runs already takes weeks on a cluster; every run id is held in memory
MAX_RUNS = 1_000_000

@dataclass(frozen=True)
class Dispersions:
    """Uniform ranges (lo, hi); counts are inclusive integer ranges."""
    inertia_scale: tuple[float, float]
    density_scale: tuple[float, float]
    aero_scale: tuple[float, float]
    bank0_err_deg: tuple[float, float]
    flight_path_offset_deg: tuple[float, float]
    fdir_delay_s: tuple[float, float]
    fault_t_s: tuple[float, float]
    n_failed_off: tuple[int, int]
    n_stuck_on: tuple[int, int]
    n_degraded: tuple[int, int]
    degraded_eta: tuple[float, float]
    # entry state and atmosphere (guided campaigns; zero ranges leave the base unchanged)
    speed_offset_mps: tuple[float, float] = (0.0, 0.0)
    heading_offset_deg: tuple[float, float] = (0.0, 0.0)
    position_offset_km: tuple[float, float] = (0.0, 0.0)     # north and east, each
    density_wave_amp: tuple[float, float] = (0.0, 0.0)       # amplitude of each altitude wave
    density_wave_km: tuple[float, ...] = ()                  # their wavelengths (phases drawn)


@dataclass(frozen=True)
class Criteria:
    """What makes a run a success (spec: completes, finite, bounded error). Cycle slips are not
    one: a batch or lockstep run waits for its FSW, so a slow cycle changes nothing in the flight
    (they are kept as a host figure, ``cycle_slips`` and ``control_cycle.compute_overruns``)."""
    completed: bool
    finite: bool
    bank_err_max_after_fault_deg: float
    deploy_miss_km: float | None = None       # guided campaigns: deploy within this of the target
    deploy_alt_min_km: float | None = None    # ... at or above this altitude
    deploy_in_box: bool = False               # ... on the FSW's command inside the deploy box

    def failures(self, summary: dict) -> list[str]:
        """The criteria this run's summary.json breaks (empty: success)."""
        out = []
        if self.completed and not summary.get("completed"):
            out.append("completed")
        if self.finite and summary.get("nonfinite", True):
            out.append("finite")
        e = summary.get("bank_err_max_after_fault_deg")
        t_f, t_end = summary.get("fault_t_s"), summary.get("t_end_s")
        fault_flown = t_f is None or t_end is None or t_f <= t_end   # else vacuous: the run ended first
        if fault_flown and (e is None or not e <= self.bank_err_max_after_fault_deg):
            out.append("bank_err_max_after_fault_deg")
        if self.deploy_miss_km is not None:
            m = summary.get("deploy_miss_km")
            if m is None or not m <= self.deploy_miss_km:
                out.append("deploy_miss_km")
        if self.deploy_alt_min_km is not None:
            a = summary.get("deploy_alt_km")
            if a is None or not a >= self.deploy_alt_min_km:
                out.append("deploy_alt_min_km")
        if self.deploy_in_box and not (summary.get("deploy") or {}).get("ok"):
            out.append("deploy_in_box")
        return out


@dataclass(frozen=True)
class Campaign:
    name: str
    description: str
    file: str
    scenario: str              # base scenario (name in data/scenarios or path)
    max_duration_s: float | None   # replaces the base scenario's time cap (dispersed entries last longer)
    runs: int
    master_seed: int
    dispersions: Dispersions
    success: Criteria
    break_runs: tuple[int, ...] = ()   # [testing]: runs given an invalid FDIR delay (run() raises)
    fsw: dict = field(default_factory=dict)   # FSW parameter overrides of every run ([fsw], e.g. deploy.trigger)

    def record(self) -> dict:
        """Plain JSON of everything that decides the draws and the verdicts (campaign.json)."""
        d = asdict(self)
        d.pop("file")
        return json.loads(json.dumps(d))


def _range(t: Table, key: str, lo: float | None = None, hi: float | None = None, lo_open: bool = False,
           hi_open: bool = False, integer: bool = False) -> tuple:
    v = t.raw(key)
    if integer and (not isinstance(v, list) or not all(isinstance(x, int) and not isinstance(x, bool) for x in v)):
        raise t.error(key, f"must be [lo, hi] with integers, got {v!r}")
    a = t.vec(key, 2, lo=lo, hi=hi, lo_open=lo_open, hi_open=hi_open)
    if a[0] > a[1]:
        raise t.error(key, f"lo must not exceed hi, got {v!r}")
    return (int(a[0]), int(a[1])) if integer else (float(a[0]), float(a[1]))


def load_campaign(name_or_path: str | Path) -> Campaign:
    """Read and validate a campaign file (data/campaigns/<name>.toml or a path)."""
    path = resolve("campaigns", name_or_path)
    root = Table(load_toml(path), path)
    c = root.table("campaign")
    d = root.table("dispersions")
    f = d.table("faults")
    disp = Dispersions(
        inertia_scale=_range(d, "inertia_scale", lo=0, lo_open=True),
        density_scale=_range(d, "density_scale", lo=0, lo_open=True),
        aero_scale=_range(d, "aero_scale", lo=0, lo_open=True),
        bank0_err_deg=_range(d, "bank0_err_deg", lo=-180, hi=180),
        flight_path_offset_deg=_range(d, "flight_path_offset_deg", lo=-10, hi=10),
        fdir_delay_s=_range(d, "fdir_delay_s", lo=0, hi=60),
        fault_t_s=_range(f, "t_s", lo=0),
        n_failed_off=_range(f, "failed_off", lo=0, hi=N_JETS, integer=True),
        n_stuck_on=_range(f, "stuck_on", lo=0, hi=N_JETS, integer=True),
        n_degraded=_range(f, "degraded", lo=0, hi=N_JETS, integer=True),
        degraded_eta=_range(f, "degraded_eta", lo=0, hi=1, lo_open=True, hi_open=True),
        speed_offset_mps=_range(d, "speed_offset_mps", lo=-1000, hi=1000) if d.has("speed_offset_mps") else (0.0, 0.0),
        heading_offset_deg=_range(d, "heading_offset_deg", lo=-30, hi=30) if d.has("heading_offset_deg") else (0.0, 0.0),
        position_offset_km=_range(d, "position_offset_km", lo=-500, hi=500) if d.has("position_offset_km") else (0.0, 0.0),
        density_wave_amp=_range(d, "density_wave_amp", lo=0, hi=0.2) if d.has("density_wave_amp") else (0.0, 0.0),
        density_wave_km=tuple(float(x) for x in d.vec("density_wave_km", len(d.raw("density_wave_km")), lo=0.1,
                                                      lo_open=False)) if d.has("density_wave_km") else (),
    )
    if len(disp.density_wave_km) * disp.density_wave_amp[1] >= 1.0:
        raise d.error("density_wave_amp", "the waves' largest amplitudes must sum below 1 (density stays positive)")
    if disp.n_failed_off[1] + disp.n_stuck_on[1] + disp.n_degraded[1] > N_JETS:
        raise f.error("failed_off", f"the largest fault sets together exceed the {N_JETS} jets")
    s = root.table("success")
    crit = Criteria(
        completed=s.bool("completed", default=True),
        finite=s.bool("finite", default=True),
        bank_err_max_after_fault_deg=s.num("bank_err_max_after_fault_deg", lo=0, lo_open=True),
        deploy_miss_km=s.num("deploy_miss_km", default=None, lo=0, lo_open=True),
        deploy_alt_min_km=s.num("deploy_alt_min_km", default=None, lo=0),
        deploy_in_box=s.bool("deploy_in_box", default=False),
    )
    fsw = dict(fsw_overrides(root))
    tst = root.table("testing", default={})
    br = tst.raw("break_runs", default=[])
    if not isinstance(br, list) or not all(isinstance(x, int) and not isinstance(x, bool) and x >= 0 for x in br):
        raise tst.error("break_runs", f"must be a list of run ids (integers >= 0), got {br!r}")
    camp = Campaign(
        name=c.str("name"), description=c.str("description", default=""), file=str(path),
        scenario=c.str("scenario"),
        max_duration_s=c.num("max_duration_s", default=None, lo=0, lo_open=True),
        runs=c.num("runs", lo=1, hi=MAX_RUNS, integer=True),
        master_seed=c.num("master_seed", lo=0, hi=2**63 - 1, integer=True),
        dispersions=disp, success=crit, break_runs=tuple(sorted(set(br))), fsw=fsw,
    )
    for t in (c, f, d, s, tst, root):
        t.reject_unknown()
    return camp


DEPLOY_TRIGGERS = ("range", "velocity")


def with_deploy_trigger(camp: Campaign, trigger: str) -> Campaign:
    """The campaign with every run's FSW deploying by ``trigger`` (FSW parameter deploy.trigger)."""
    if trigger not in DEPLOY_TRIGGERS:
        raise ValueError(f"deploy trigger must be one of {', '.join(DEPLOY_TRIGGERS)}, got {trigger!r}")
    return replace(camp, fsw=merge_fsw(camp.fsw, {"deploy": {"trigger": trigger}}))


def merge_fsw(base: dict, over: dict) -> dict:
    """FSW overrides ``base`` ({section: {key: value}}) with ``over``'s on top."""
    out = {k: (dict(v) if isinstance(v, dict) else v) for k, v in base.items()}
    for sec, vals in over.items():
        out.setdefault(sec, {}).update(vals)
    return out


def campaign_base(camp_record: dict, snapshot: Scenario) -> Scenario:
    """The base scenario every run starts from: the snapshot with the campaign's time cap and
    its FSW overrides."""
    cap = camp_record.get("max_duration_s")
    scn = snapshot if cap is None else snapshot.with_(max_duration_s=float(cap))
    over = camp_record.get("fsw") or {}
    return scn.with_(fsw=merge_fsw(scn.fsw, over)) if over else scn


def run_rng(master_seed: int, run_id: int) -> tuple[int, np.random.Generator]:
    """(noise seed, dispersion generator) of one run: independent streams per run_id."""
    if isinstance(run_id, bool) or not isinstance(run_id, (int, np.integer)) or run_id < 0:
        raise ValueError(f"run_id must be an integer >= 0, got {run_id!r}")
    ss = np.random.SeedSequence(int(master_seed), spawn_key=(int(run_id),))
    seed = int(ss.generate_state(1, np.uint32)[0])
    return seed, np.random.Generator(np.random.PCG64(ss.spawn(1)[0]))


def draw_run(camp: Campaign, base: Scenario, run_id: int, master_seed: int | None = None) -> tuple[int, dict]:
    """(noise seed, dispersions) of run ``run_id``. Dispersions are plain values
    (floats, ints, tuples of jet numbers): exactly what is recorded and re-applied."""
    seed, rng = run_rng(camp.master_seed if master_seed is None else master_seed, run_id)
    d = camp.dispersions
    h0 = inertia_vector(base.vehicle.inertia_kgm2)
    for _ in range(1000):   # products of inertia may make a draw non-physical: redraw (deterministic)
        isc = rng.uniform(*d.inertia_scale, size=6)
        if np.min(np.linalg.eigvalsh(inertia_matrix(h0 * isc))) > 0:
            break
    else:
        raise ValueError("inertia_scale: no positive-definite truth inertia in 1000 draws; narrow the range")
    out = {f"inertia_scale_{k}": float(x) for k, x in zip(INERTIA_KEYS, isc)}
    out["density_scale"] = float(rng.uniform(*d.density_scale))
    for k in AERO_KEYS:
        out[f"{k}_scale"] = float(rng.uniform(*d.aero_scale))
    out["bank0_err_deg"] = float(rng.uniform(*d.bank0_err_deg))
    out["flight_path_offset_deg"] = float(rng.uniform(*d.flight_path_offset_deg))
    out["fdir_delay_s"] = float(rng.uniform(*d.fdir_delay_s))
    out["fault_t_s"] = float(rng.uniform(*d.fault_t_s))
    n_off = int(rng.integers(d.n_failed_off[0], d.n_failed_off[1] + 1))
    n_stuck = int(rng.integers(d.n_stuck_on[0], d.n_stuck_on[1] + 1))
    n_deg = int(rng.integers(d.n_degraded[0], d.n_degraded[1] + 1))
    jets = [int(j) + 1 for j in rng.permutation(N_JETS)]
    out["jets_failed_off"] = tuple(sorted(jets[:n_off]))
    out["jets_stuck_on"] = tuple(sorted(jets[n_off:n_off + n_stuck]))
    out["jets_degraded"] = tuple(sorted(jets[n_off + n_stuck:n_off + n_stuck + n_deg]))
    out["degraded_eta"] = tuple(float(x) for x in rng.uniform(*d.degraded_eta, size=n_deg))
    # drawn after the original set, so campaigns without them keep every earlier draw
    if d.speed_offset_mps != (0.0, 0.0) or d.heading_offset_deg != (0.0, 0.0) or d.position_offset_km != (0.0, 0.0):
        out["speed_offset_mps"] = float(rng.uniform(*d.speed_offset_mps))
        out["heading_offset_deg"] = float(rng.uniform(*d.heading_offset_deg))
        out["north_offset_km"] = float(rng.uniform(*d.position_offset_km))
        out["east_offset_km"] = float(rng.uniform(*d.position_offset_km))
    if d.density_wave_km:
        amp = rng.uniform(*d.density_wave_amp, size=len(d.density_wave_km))
        ph = rng.uniform(0.0, 2.0 * math.pi, size=len(d.density_wave_km))
        out["density_waves"] = tuple(float(x) for w in zip(amp, d.density_wave_km, ph)
                                     for x in (w[0], w[1] * 1e3, w[2]))
    if run_id in camp.break_runs:
        out["fdir_delay_s"] = BROKEN_FDIR_DELAY_S
    return seed, out


def apply_dispersion(base: Scenario, disp: dict, seed: int, name: str) -> Scenario:
    """The base scenario with one run's dispersions: truth = nominal x scales (its own
    truth and faults are replaced), initial bank = reference start + error."""
    try:
        isc = np.array([float(disp[f"inertia_scale_{k}"]) for k in INERTIA_KEYS])
        w = tuple(float(x) for x in disp.get("density_waves", ()))
        truth = Truth(inertia_scale=isc, density_scale=float(disp["density_scale"]),
                      **{f"{k}_scale": float(disp[f"{k}_scale"]) for k in AERO_KEYS},
                      density_waves=tuple(tuple(w[i:i + 3]) for i in range(0, len(w) - 2, 3)))
        dv = float(disp.get("speed_offset_mps", 0.0))
        dpsi = math.radians(float(disp.get("heading_offset_deg", 0.0)))
        dn, de = float(disp.get("north_offset_km", 0.0)) * 1e3, float(disp.get("east_offset_km", 0.0)) * 1e3
        t_f = float(disp["fault_t_s"])
        off, stuck, deg = (tuple(int(j) for j in disp[k]) for k in ("jets_failed_off", "jets_stuck_on", "jets_degraded"))
        eta = tuple(float(x) for x in disp["degraded_eta"])
        bank_err = math.radians(float(disp["bank0_err_deg"]))
        gamma_off = math.radians(float(disp["flight_path_offset_deg"]))
        delay = float(disp["fdir_delay_s"])
    except KeyError as e:
        raise ValueError(f"dispersion record lacks {e.args[0]!r}") from None
    if len(eta) != len(deg):
        raise ValueError(f"degraded_eta has {len(eta)} values for {len(deg)} degraded jets")
    if not all(math.isfinite(x) for x in (*isc, truth.density_scale, t_f, bank_err, gamma_off, delay, *eta)):
        raise ValueError("dispersion record holds a non-finite value")
    faults = []
    if off:
        faults.append(FaultEvent(t_s=t_f, jets=off, kind="failed_off"))
    if stuck:
        faults.append(FaultEvent(t_s=t_f, jets=stuck, kind="stuck_on"))
    faults += [FaultEvent(t_s=t_f, jets=(j,), kind="degraded", eta=e) for j, e in zip(deg, eta)]
    fsw = {k: (dict(v) if isinstance(v, dict) else v) for k, v in base.fsw.items()}
    fsw.setdefault("fdir", {})["delay_s"] = delay
    extra = {}
    if dv or dpsi or dn or de:
        r = base.planet.radius_m + base.altitude_m
        extra = dict(speed_rel_mps=base.speed_rel_mps + dv, heading_rad=base.heading_rad + dpsi,
                     latitude_rad=base.latitude_rad + dn / r,
                     longitude_rad=base.longitude_rad + de / (r * math.cos(base.latitude_rad)))
    return base.with_(name=name, seed=int(seed), truth=truth, faults=tuple(faults), fsw=fsw,
                      bank0_rad=base.bank_schedule[0][1] + bank_err,
                      flight_path_rad=base.flight_path_rad + gamma_off, **extra)


def dispersion_columns(disp: dict) -> dict:
    """The record's columns (``disp.<name>``): jet sets as JSON text, plus their sizes."""
    out = {}
    for k, v in disp.items():
        out[f"disp.{k}"] = json.dumps(list(v)) if isinstance(v, tuple) else v
    out["disp.n_failed_off"] = len(disp["jets_failed_off"])
    out["disp.n_stuck_on"] = len(disp["jets_stuck_on"])
    out["disp.n_degraded"] = len(disp["jets_degraded"])
    return out


def dispersion_from_columns(row: dict) -> dict:
    """Inverse of ``dispersion_columns`` (JSON floats round-trip exactly). A null column is a
    dispersion the campaign does not draw (the record declares every one)."""
    out = {}
    for k, v in row.items():
        if not k.startswith("disp.") or k[5:] in ("n_failed_off", "n_stuck_on", "n_degraded") or v is None:
            continue
        out[k[5:]] = tuple(json.loads(v)) if isinstance(v, str) else v
    return out


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        return repr(float(v))           # shortest repr: the file reads back bit for bit
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"no TOML form for {type(v).__name__}")


def _toml(d: dict, prefix: str = "") -> list[str]:
    """A scenario dictionary as TOML: plain keys, then sub-tables, then arrays of tables."""
    out = [f"{k} = {_toml_value(v)}" for k, v in d.items()
           if not (isinstance(v, dict) and not prefix.endswith("truth") and k != "inertia_scale")
           and not (isinstance(v, list) and v and isinstance(v[0], dict))]
    for k, v in d.items():
        name = f"{prefix}.{k}" if prefix else k
        if isinstance(v, dict) and k != "inertia_scale":
            sub = _toml(v, name)
            out += (["", f"[{name}]"] + sub) if sub and sub[0] else sub    # a table of tables: no header
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            for item in v:
                out += ["", f"[[{name}]]"] + _toml(item, name)
    return out


def pinned_scenario_toml(camp: Campaign, base_file: str | Path, run_id: int, master_seed: int | None = None) -> str:
    """Run ``run_id`` of a campaign as a stand-alone scenario file: the base scenario file with
    the run's seed, truth dispersions (density waves included), initial bank and flight-path
    angle, entry state (speed, heading, position) when the campaign disperses it, FDIR delay,
    time cap and fault events. Flying it flies that run bit for bit (angles in radians)."""
    master_seed = camp.master_seed if master_seed is None else master_seed
    raw = load_toml(Path(base_file))
    from common.model import load_scenario
    base = campaign_base(camp.record(), load_scenario(base_file))
    seed, d = draw_run(camp, base, run_id, master_seed)
    sc, ini = raw["scenario"], raw["initial"]
    sc["name"] = f"mc-{camp.name}-{master_seed}-run{run_id}"
    sc["description"] = (f"Run {run_id} of campaign {camp.name} (master seed {master_seed}), pinned: "
                         f"ellipsled montecarlo {camp.name} --seed {master_seed} --pin {run_id}")
    sc["seed"] = int(seed)
    if camp.max_duration_s is not None:
        sc["max_duration_s"] = float(camp.max_duration_s)
    # the initial state as apply_dispersion makes it (one place computes the offsets), its
    # angles in radians: a value through degrees and back can differ in the last bit, and a
    # guided run's deploy point moved 0.25 km across from that alone
    run = apply_dispersion(base, d, seed, sc["name"])
    g = raw.setdefault("guidance", {})
    if "bank_schedule" not in g:
        # npc: the base's reference starts at the base's initial bank, not at the run's
        # dispersed one (the bank error is the attitude's, not the reference's)
        g["bank_schedule"] = [[0.0, float(ini["bank_deg"])]]
    angles = {"flight_path": run.flight_path_rad, "bank": run.bank0_rad}
    if "speed_offset_mps" in d:
        ini["speed_rel_mps"] = run.speed_rel_mps
        angles.update(heading=run.heading_rad, latitude=run.latitude_rad, longitude=run.longitude_rad)
    for k, v in angles.items():
        ini.pop(f"{k}_deg", None)
        ini[f"{k}_rad"] = v
    raw["truth"] = {"inertia_scale": {k: d[f"inertia_scale_{k}"] for k in INERTIA_KEYS},
                    "density_scale": d["density_scale"], **{f"{k}_scale": d[f"{k}_scale"] for k in AERO_KEYS}}
    if d.get("density_waves"):
        w = d["density_waves"]
        raw["truth"]["density_waves"] = [list(w[i:i + 3]) for i in range(0, len(w) - 2, 3)]
    raw["fsw"] = merge_fsw(raw.get("fsw", {}), camp.fsw)
    raw["fsw"].setdefault("fdir", {})["delay_s"] = d["fdir_delay_s"]
    faults = []
    for kind, key in (("failed_off", "jets_failed_off"), ("stuck_on", "jets_stuck_on")):
        if d[key]:
            faults.append({"t_s": d["fault_t_s"], "jets": list(d[key]), "kind": kind})
    faults += [{"t_s": d["fault_t_s"], "jets": [j], "kind": "degraded", "eta": e}
               for j, e in zip(d["jets_degraded"], d["degraded_eta"])]
    raw["faults"] = faults
    head = [f"# {sc['description']}", "# Generated from the campaign's draw (ellipsled/montecarlo/campaign.py); do not edit."]
    return "\n".join(head + _toml(raw)) + "\n"


def pin_runs(camp: Campaign, run_ids, out_dir: str | Path, master_seed: int | None = None) -> list[Path]:
    """Write runs of a campaign as scenario files ``<campaign>-<seed>-run<id>.toml`` in ``out_dir``."""
    master_seed = camp.master_seed if master_seed is None else master_seed
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = []
    for rid in run_ids:
        f = out / f"{camp.name}-{master_seed}-run{int(rid):03d}.toml"
        f.write_text(pinned_scenario_toml(camp, resolve("scenarios", camp.scenario), int(rid), master_seed))
        files.append(f)
    return files


__all__ = ["pinned_scenario_toml", "pin_runs", "Campaign", "Criteria", "Dispersions", "ConfigError", "load_campaign", "run_rng", "draw_run",
           "apply_dispersion", "dispersion_columns", "dispersion_from_columns"]
