"""Typed, validated views of the data files: planet, vehicle, scenario.

Loaded once, at start-up; everything downstream takes these objects, never raw dicts.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from interfaces.vocabulary import FAULT_KINDS, N_JETS, refuse_state_word

from .config import FSW_DEFAULTS_FILE, Table, load_toml, resolve

INERTIA_KEYS = ("I11", "I22", "I33", "I12", "I13", "I23")


_INERTIA_IDX = np.array([[0, 3, 4], [3, 1, 5], [4, 5, 2]])


def inertia_matrix(h: np.ndarray) -> np.ndarray:
    """Inertia tensor from h = [I11 I22 I33 I12 I13 I23] (docs/fsw/index.md ordering); a new
    array of h's dtype."""
    return np.asarray(h)[_INERTIA_IDX]


def inertia_vector(I: np.ndarray) -> np.ndarray:
    return np.array([I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]])


@dataclass(frozen=True)
class Planet:
    name: str
    mu_m3ps2: float
    radius_m: float
    omega_radps: float
    j2: float
    use_j2: bool
    g0_mps2: float
    density_model: str
    rho0_kgpm3: float
    scale_height_m: float


@dataclass(frozen=True)
class Aero:
    alpha_trim_rad: float
    C_L: float
    C_D: float
    C_Lalpha: float
    C_Ybeta: float
    C_malpha: float
    C_nbeta: float
    C_lbeta: float
    C_lp: float
    C_mq: float
    C_nr: float


@dataclass(frozen=True)
class DeployBox:
    """The safe parachute-deploy box (docs/fsw/entry-guidance.md, deploy trigger): the plant
    opens the parachute when commanded inside it, or at its edge when left without a command."""
    mach_min: float
    mach_max: float
    qbar_min_pa: float
    qbar_max_pa: float
    h_min_m: float

    def inside(self, mach: float, qbar_pa: float, h_m: float) -> bool:
        return (self.mach_min <= mach <= self.mach_max and self.qbar_min_pa <= qbar_pa <= self.qbar_max_pa
                and h_m >= self.h_min_m)

    def passed(self, mach: float, h_m: float) -> str:
        """The edge a vehicle going slower and lower has passed ('mach_min', 'h_min'), or ''."""
        if mach < self.mach_min:
            return "mach_min"
        if h_m < self.h_min_m:
            return "h_min"
        return ""


@dataclass(frozen=True)
class Vehicle:
    name: str
    mass_kg: float
    inertia_kgm2: np.ndarray      # 3x3, body axes
    S_ref_m2: float
    l_ref_m: float
    aero: Aero
    thrust_N: np.ndarray          # (18,)
    torque_matrix_Nm: np.ndarray  # (3, 18): column k = torque of jet k+1 at full thrust
    isp_s: float
    jet_force_B_N: np.ndarray | None = None  # (3, 18) when jets are given by geometry
    nose_radius_m: float = 1.875             # Sutton-Graves heat rate (docs/fsw/entry-guidance.md)
    max_load_g: float = 15.0                 # structural limit of the aerodynamic load factor [g0]
    max_heat_rate_wcm2: float = 100.0        # stagnation-point heat-rate limit [W/cm^2]
    inertia_uncertainty_frac: float = 0.0    # each inertia element known to within this fraction
    deploy_box: "DeployBox | None" = None    # where the parachute may open (vehicle file [deploy])


@dataclass(frozen=True)
class FaultEvent:
    t_s: float
    jets: tuple[int, ...]   # 1-based jet numbers
    kind: str               # failed_off | stuck_on | degraded | nominal (interfaces/vocabulary.py FAULT_KINDS)
    eta: float = 1.0


@dataclass(frozen=True)
class Truth:
    """Dispersion of the truth relative to the nominal (FSW) models."""
    inertia_scale: np.ndarray       # (6,) on h ordering
    density_scale: float
    C_lbeta_scale: float
    C_malpha_scale: float
    C_nbeta_scale: float
    # altitude-correlated density perturbation: (amplitude, wavelength [m], phase [rad]) waves,
    # rho_truth = scale x rho_model x (1 + sum a sin(2 pi h / L + phase))
    density_waves: tuple[tuple[float, float, float], ...] = ()


MAX_RHO_WAVES = 4      # density waves the plant's parameter vector holds (sim/dynamics.py)


@dataclass(frozen=True)
class SensorNoise:
    gyro_noise_radps: float
    gyro_bias_radps: np.ndarray
    attitude_noise_rad: float
    nav_noise: bool
    nav_pos_noise_m: float
    nav_vel_noise_mps: float
    chamber_noise: float


@dataclass(frozen=True)
class Scenario:
    name: str
    description: str
    file: str
    planet: Planet
    vehicle: Vehicle
    seed: int
    max_duration_s: float
    dt_control_s: float
    dt_integrator_s: float
    # initial state
    altitude_m: float
    speed_rel_mps: float
    flight_path_rad: float
    heading_rad: float
    latitude_rad: float
    longitude_rad: float
    bank0_rad: float
    # end conditions (the deploy trigger: Mach, or a speed when end_speed_mps is set)
    end_mach: float
    end_altitude_m: float
    # guidance
    bank_schedule: tuple[tuple[float, float], ...]   # (t_s, bank_rad)
    bank_rate_limit_radps: float
    bank_accel_limit_radps2: float
    truth: Truth
    sensors: SensorNoise
    faults: tuple[FaultEvent, ...]
    fsw: dict = field(default_factory=dict)  # overrides of data/fsw/default.toml, validated by fsw
    guidance_mode: str = "profile"           # profile | npc (docs/fsw/entry-guidance.md)
    end_speed_mps: float | None = None
    target_lat_rad: float | None = None      # deploy target (required by mode "npc")
    target_lon_rad: float | None = None
    # who deploys: "fsw" (the flight software's deploy command; the plant at the vehicle's box
    # edge otherwise) or "plant" (the plant at the end condition above, the paper's cases)
    deploy_by: str = "plant"

    @property
    def substeps(self) -> int:
        return int(round(self.dt_control_s / self.dt_integrator_s))

    def with_(self, **kw) -> "Scenario":
        return replace(self, **kw)


def load_planet(name_or_path: str | Path) -> Planet:
    path = resolve("planets", name_or_path)
    root = Table(load_toml(path), path)
    p = root.table("planet")
    a = root.table("atmosphere")
    out = Planet(
        name=p.str("name"),
        mu_m3ps2=p.num("mu_m3ps2", lo=0, lo_open=True),
        radius_m=p.num("radius_m", lo=0, lo_open=True),
        omega_radps=p.num("omega_radps", lo=-1e-2, hi=1e-2),
        j2=p.num("j2", default=0.0, lo=-0.1, hi=0.1),
        use_j2=p.bool("use_j2", default=False),
        g0_mps2=p.num("g0_mps2", default=9.80665, lo=0, lo_open=True),
        density_model=a.str("model", choices=("exponential", "polynomial")),
        rho0_kgpm3=a.num("rho0_kgpm3", lo=0, lo_open=True),
        scale_height_m=a.num("scale_height_m", lo=0, lo_open=True),
    )
    p.reject_unknown(); a.reject_unknown(); root.reject_unknown()
    return out


def _jets_from_geometry(jt: Table) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """T = r x F for jets given by position (about the centre of mass), direction, thrust."""
    entries = jt.tables("jet")
    if len(entries) != N_JETS:
        raise jt.error("jet", f"must list {N_JETS} jets, got {len(entries)}")
    thrust = np.empty(N_JETS)
    T = np.empty((3, N_JETS))
    F = np.empty((3, N_JETS))
    for k, e in enumerate(entries):
        r = e.vec("position_m", 3)
        d = e.vec("direction", 3)
        n = float(np.linalg.norm(d))
        if n < 1e-9:
            raise e.error("direction", "must be a non-zero vector")
        thrust[k] = e.num("thrust_N", lo=0, lo_open=True)
        F[:, k] = thrust[k] * d / n
        T[:, k] = np.cross(r, F[:, k])
        e.reject_unknown()
    return thrust, T, F


def load_vehicle(name_or_path: str | Path) -> Vehicle:
    path = resolve("vehicles", name_or_path)
    root = Table(load_toml(path), path)
    v = root.table("vehicle")
    it = v.table("inertia_kgm2")
    h = np.array([it.num(k, lo=0, lo_open=True) if i < 3 else it.num(k) for i, k in enumerate(INERTIA_KEYS)])
    it.reject_unknown()
    I = inertia_matrix(h)
    if np.min(np.linalg.eigvalsh(I)) <= 0:
        raise v.error("inertia_kgm2", "inertia tensor is not positive definite")
    ev = np.linalg.eigvalsh(I)
    if ev[0] + ev[1] < ev[2] * (1 - 1e-12):
        raise v.error("inertia_kgm2", "principal moments violate the triangle inequality (not a physical body)")
    a = root.table("aero")
    aero = Aero(
        alpha_trim_rad=math.radians(a.num("alpha_trim_deg", lo=-90, hi=90)),
        C_L=a.num("C_L"), C_D=a.num("C_D", lo=0, lo_open=True), C_Lalpha=a.num("C_Lalpha"),
        C_Ybeta=a.num("C_Ybeta"), C_malpha=a.num("C_malpha"), C_nbeta=a.num("C_nbeta"),
        C_lbeta=a.num("C_lbeta"), C_lp=a.num("C_lp"), C_mq=a.num("C_mq"), C_nr=a.num("C_nr"),
    )
    jt = root.table("jets")
    model = jt.str("model", choices=("matrix", "geometry"))
    isp = jt.num("isp_s", lo=0, lo_open=True)
    force = None
    if model == "matrix":
        thrust = jt.vec("thrust_N", N_JETS, lo=0, lo_open=True)
        T = jt.matrix("torque_matrix_Nm", 3, N_JETS)
    else:
        thrust, T, force = _jets_from_geometry(jt)
    jt.reject_unknown()
    out = Vehicle(
        name=v.str("name"),
        mass_kg=v.num("mass_kg", lo=0, lo_open=True),
        inertia_kgm2=I,
        S_ref_m2=v.num("S_ref_m2", lo=0, lo_open=True),
        l_ref_m=v.num("l_ref_m", lo=0, lo_open=True),
        aero=aero, thrust_N=thrust, torque_matrix_Nm=T, isp_s=isp, jet_force_B_N=force,
    )
    diameter = v.num("diameter_m", default=None, lo=0, lo_open=True)
    v.num("length_m", default=None, lo=0, lo_open=True)
    lim = root.table("limits", default={})
    out = replace(out,
                  nose_radius_m=v.num("nose_radius_m", default=diameter / 2 if diameter else 1.875, lo=0, lo_open=True),
                  max_load_g=lim.num("load_g", default=15.0, lo=0, lo_open=True),
                  max_heat_rate_wcm2=lim.num("heat_rate_wcm2", default=100.0, lo=0, lo_open=True),
                  inertia_uncertainty_frac=v.num("inertia_uncertainty_frac", default=0.0, lo=0, hi=0.9))
    lim.reject_unknown()
    dep = root.table("deploy", default={})
    if dep.data:
        box = DeployBox(mach_min=dep.num("mach_min", lo=0), mach_max=dep.num("mach_max", lo=0, lo_open=True),
                        qbar_min_pa=dep.num("qbar_min_pa", lo=0), qbar_max_pa=dep.num("qbar_max_pa", lo=0, lo_open=True),
                        h_min_m=dep.num("altitude_min_m", lo=0))
        if not (box.mach_min < box.mach_max and box.qbar_min_pa < box.qbar_max_pa):
            raise dep.error("mach_min", "the deploy box needs mach_min < mach_max and qbar_min_pa < qbar_max_pa")
        out = replace(out, deploy_box=box)
    dep.reject_unknown()
    for t in (v, a, root):
        t.reject_unknown()
    return out


def _bank_schedule(g: Table) -> list[tuple[float, float]]:
    """[guidance] bank_schedule: [[t_s, bank_deg], ...] with increasing times -> (t_s, rad)."""
    sched_raw = g.raw("bank_schedule")
    if not isinstance(sched_raw, list) or not sched_raw:
        raise g.error("bank_schedule", "must be a non-empty list of [t_s, bank_deg] pairs")
    sched = []
    for i, pair in enumerate(sched_raw):
        if (not isinstance(pair, list) or len(pair) != 2
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in pair)):
            raise g.error("bank_schedule", f"entry {i + 1} must be [t_s, bank_deg] with finite numbers")
        if abs(pair[1]) > 180:
            raise g.error("bank_schedule", f"entry {i + 1}: bank must be within [-180, 180] deg, got {pair[1]}")
        if sched and pair[0] <= sched[-1][0]:
            raise g.error("bank_schedule", f"entry {i + 1}: times must increase")
        sched.append((float(pair[0]), math.radians(pair[1])))
    return sched


def _angle(t: Table, name: str, limit_deg: float, open_: bool = False) -> float:
    """An angle [rad] given as ``<name>_deg`` or, exactly, as ``<name>_rad`` (a pinned
    campaign run writes radians so that it starts bit for bit where the campaign's run did);
    within +-limit_deg (open bounds with ``open_``)."""
    if t.has(f"{name}_rad"):
        if t.has(f"{name}_deg"):
            raise t.error(f"{name}_rad", f"give {name}_deg or {name}_rad, not both")
        lim = math.radians(limit_deg)
        return t.num(f"{name}_rad", lo=-lim, hi=lim, lo_open=open_, hi_open=open_)
    return math.radians(t.num(f"{name}_deg", lo=-limit_deg, hi=limit_deg, lo_open=open_, hi_open=open_))


def _density_waves(tr: Table) -> tuple[tuple[float, float, float], ...]:
    """[truth] density_waves = [[amplitude, wavelength_m, phase_rad], ...] (a dispersed
    campaign's altitude-correlated density, written by its pinned runs): at most
    MAX_RHO_WAVES, finite, wavelengths above 0, amplitudes summing below 1."""
    raw = tr.raw("density_waves", default=[])
    if not isinstance(raw, list) or len(raw) > MAX_RHO_WAVES:
        raise tr.error("density_waves", f"must be a list of at most {MAX_RHO_WAVES} [amplitude, wavelength_m, "
                                        "phase_rad] triples")
    waves = []
    for i, w in enumerate(raw):
        if (not isinstance(w, list) or len(w) != 3
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in w)):
            raise tr.error("density_waves", f"entry {i + 1} must be [amplitude, wavelength_m, phase_rad], finite")
        if w[1] <= 0:
            raise tr.error("density_waves", f"entry {i + 1}: wavelength must be > 0, got {w[1]}")
        waves.append((float(w[0]), float(w[1]), float(w[2])))
    if sum(abs(a) for a, _, _ in waves) >= 1.0:
        raise tr.error("density_waves", "amplitudes must sum below 1 (the density stays positive)")
    return tuple(waves)


def fsw_overrides(root: Table) -> dict:
    """[fsw.<section>] overrides of the flight software's parameters: every section and key
    one of the defaults file's (data/fsw/default.toml), so that a misspelt override is
    refused with the nearest name instead of flown silently. Values are checked against
    their bounds by the flight software's parameter registry."""
    fsw = root.table("fsw", default={})
    defaults = load_toml(FSW_DEFAULTS_FILE)
    for section in defaults:
        if fsw.has(section):
            sec = fsw.table(section)
            for key in defaults[section]:
                sec.has(key)
            sec.reject_unknown()
    fsw.reject_unknown()
    return fsw.data


def load_scenario(name_or_path: str | Path) -> Scenario:
    path = resolve("scenarios", name_or_path)
    root = Table(load_toml(path), path)
    s = root.table("scenario")
    planet = load_planet(s.str("planet", default="mars"))
    vehicle = load_vehicle(s.str("vehicle", default="ellipsled"))
    dt_c = s.num("dt_control_s", default=0.02, lo=1e-4, hi=1.0)
    dt_i = s.num("dt_integrator_s", default=0.005, lo=1e-5, hi=1.0)
    n_sub = dt_c / dt_i
    if abs(n_sub - round(n_sub)) > 1e-9 or round(n_sub) < 1:
        raise s.error("dt_integrator_s", f"must divide dt_control_s ({dt_c}) into a whole number of substeps")

    ini = root.table("initial")
    end = root.table("end", default={})
    g = root.table("guidance")
    mode = g.str("mode", default="profile", choices=("profile", "npc"))
    bank0_rad = _angle(ini, "bank", 180.0)
    # npc without a schedule: the reference starts at the initial bank; guidance commands the rest
    sched = [(0.0, bank0_rad)] if mode == "npc" and not g.has("bank_schedule") else _bank_schedule(g)

    tr = root.table("truth", default={})
    isc = tr.table("inertia_scale", default={})
    inertia_scale = np.array([isc.num(k, default=1.0, lo=0, lo_open=True) for k in INERTIA_KEYS])
    isc.reject_unknown()
    truth = Truth(
        inertia_scale=inertia_scale,
        density_scale=tr.num("density_scale", default=1.0, lo=0, lo_open=True),
        C_lbeta_scale=tr.num("C_lbeta_scale", default=1.0),
        C_malpha_scale=tr.num("C_malpha_scale", default=1.0),
        C_nbeta_scale=tr.num("C_nbeta_scale", default=1.0),
        density_waves=_density_waves(tr),
    )
    I_truth = inertia_matrix(inertia_vector(vehicle.inertia_kgm2) * inertia_scale)
    if np.min(np.linalg.eigvalsh(I_truth)) <= 0:
        raise isc.error("I11", "scaled truth inertia is not positive definite")

    sn = root.table("sensors", default={})
    sensors = SensorNoise(
        gyro_noise_radps=sn.num("gyro_noise_radps", default=2e-5, lo=0),
        gyro_bias_radps=sn.vec("gyro_bias_radps", 3, default=[0.0, 0.0, 0.0]),
        attitude_noise_rad=math.radians(sn.num("attitude_noise_arcsec", default=20.0, lo=0) / 3600.0),
        nav_noise=sn.bool("nav_noise", default=False),
        nav_pos_noise_m=sn.num("nav_pos_noise_m", default=10.0, lo=0),
        nav_vel_noise_mps=sn.num("nav_vel_noise_mps", default=0.1, lo=0),
        chamber_noise=sn.num("chamber_noise", default=0.02, lo=0, hi=1),
    )
    faults = []
    for f in root.tables("faults"):
        kind = f.str("kind")
        if kind not in FAULT_KINDS:
            raise f.error("kind", refuse_state_word(kind, FAULT_KINDS))
        jets = f.raw("jets")
        if (not isinstance(jets, list) or not jets
                or not all(isinstance(j, int) and not isinstance(j, bool) and 1 <= j <= N_JETS for j in jets)):
            raise f.error("jets", f"must be a non-empty list of jet numbers 1..{N_JETS}, got {jets!r}")
        if len(set(jets)) != len(jets):
            raise f.error("jets", f"lists a jet more than once: {jets!r}")
        if kind != "degraded" and f.has("eta"):
            raise f.error("eta", f"applies to kind = \"degraded\" only, not {kind!r}")
        eta = f.num("eta", default=1.0 if kind != "degraded" else None, lo=0, hi=1, lo_open=True, hi_open=kind == "degraded")
        if kind == "degraded" and eta is None:
            raise f.error("eta", "required for kind = \"degraded\" (0 < eta < 1)")
        faults.append(FaultEvent(t_s=f.num("t_s", lo=0), jets=tuple(jets), kind=kind, eta=eta))
        f.reject_unknown()
    tg = root.table("target", default={})
    target = None
    if tg.data:
        target = (math.radians(tg.num("latitude_deg", lo=-90, hi=90)), math.radians(tg.num("longitude_deg", lo=-360, hi=360)))
    elif mode == "npc":
        raise root.error("target", "guidance mode \"npc\" needs a [target] with latitude_deg and longitude_deg")
    end_speed = end.num("speed_mps", default=None, lo=0, lo_open=True)
    if end_speed is not None and end.has("mach"):
        raise end.error("speed_mps", "give the deploy condition as mach or as speed_mps, not both")
    fsw = fsw_overrides(root)
    deploy_by = end.str("deploy", default="fsw" if mode == "npc" else "plant", choices=("fsw", "plant"))
    if deploy_by == "fsw" and vehicle.deploy_box is None:
        raise end.error("deploy", f"deploy = \"fsw\" needs a [deploy] box in vehicle {vehicle.name!r}")

    out = Scenario(
        name=s.str("name"), description=s.str("description", default=""), file=str(path),
        planet=planet, vehicle=vehicle,
        seed=s.num("seed", default=1, lo=0, integer=True),
        max_duration_s=s.num("max_duration_s", default=700.0, lo=0, lo_open=True),
        dt_control_s=dt_c, dt_integrator_s=dt_i,
        altitude_m=ini.num("altitude_m", lo=0, lo_open=True),
        speed_rel_mps=ini.num("speed_rel_mps", lo=0, lo_open=True),
        flight_path_rad=_angle(ini, "flight_path", 90.0, open_=True),
        heading_rad=_angle(ini, "heading", 360.0),
        latitude_rad=_angle(ini, "latitude", 89.0),
        longitude_rad=_angle(ini, "longitude", 360.0),
        bank0_rad=bank0_rad,
        end_mach=end.num("mach", default=2.0, lo=0) if end_speed is None else 0.0,
        end_speed_mps=end_speed, guidance_mode=mode, deploy_by=deploy_by,
        target_lat_rad=target[0] if target else None, target_lon_rad=target[1] if target else None,
        end_altitude_m=end.num("altitude_m", default=6000.0, lo=0),
        bank_schedule=tuple(sched),
        bank_rate_limit_radps=math.radians(g.num("rate_limit_dps", lo=0, lo_open=True)),
        bank_accel_limit_radps2=math.radians(g.num("accel_limit_dps2", lo=0, lo_open=True)),
        truth=truth, sensors=sensors, faults=tuple(sorted(faults, key=lambda f: f.t_s)), fsw=dict(fsw),
    )
    for t in (s, ini, end, g, tg, tr, sn, root):
        t.reject_unknown()
    return out
