"""The run's variant: the scenario with a run's command-line changes (fault tolerance off,
duration, identification mode, no initial bank error), the options that ask for them and
the end reason a requested duration gives. The batch runner, the SIL launcher and both SIL
nodes prepare a run with the same functions, so each flies the same scenario.
"""
from __future__ import annotations

from pathlib import Path

from common.config import ConfigError
from common.model import Scenario, load_scenario

from common import argtypes
from .history import budget_refusal

IDENTIFICATION = ("detect", "oracle")     # fdir.mode: the product's FDIR, or the test mode's fault log


def _with_fsw(scn: Scenario, section: str, key: str, value, suffix: str) -> Scenario:
    fsw = {k: (dict(v) if isinstance(v, dict) else v) for k, v in scn.fsw.items()}
    fsw.setdefault(section, {})[key] = value
    return scn.with_(fsw=fsw, name=scn.name if scn.name.endswith(suffix) else f"{scn.name}{suffix}")


def prepare(scenario: Scenario | str, ft_off: bool = False, duration_s: float | None = None,
            identification: str | None = None, initial_error: bool = True,
            dt_control_s: float | None = None) -> Scenario:
    """The scenario with the run's command-line changes applied: fault tolerance off,
    duration, identification mode (None: the scenario's), ``initial_error=False``: the
    bank starts on the reference (no initial bank error), and ``dt_control_s``: the control
    period (None: the scenario's; the plant's integrator step must divide it)."""
    scn = load_scenario(scenario) if isinstance(scenario, (str, Path)) else scenario
    if dt_control_s is not None and dt_control_s != scn.dt_control_s:
        n_sub = dt_control_s / scn.dt_integrator_s
        if not (dt_control_s > 0 and abs(n_sub - round(n_sub)) <= 1e-9 and round(n_sub) >= 1):
            raise ConfigError(scn.file, "--dt-control",
                              f"{dt_control_s:g} s is not a whole number of the plant's integrator steps "
                              f"(scenario.dt_integrator_s = {scn.dt_integrator_s:g} s)")
        suffix = f"-{1.0 / dt_control_s:g}hz"
        scn = scn.with_(dt_control_s=float(dt_control_s),
                        name=scn.name if scn.name.endswith(suffix) else f"{scn.name}{suffix}")
    if ft_off:
        scn = _with_fsw(scn, "allocator", "fault_tolerance", 0, "-ft-off")
    if identification is not None:
        if identification not in IDENTIFICATION:
            raise ValueError(f"identification: must be one of {', '.join(IDENTIFICATION)}, got {identification!r}")
        scn = _with_fsw(scn, "fdir", "mode", identification, "-oracle" if identification == "oracle" else "")
    if not initial_error:
        suffix = "-no-init-err"
        scn = scn.with_(bank0_rad=scn.bank_schedule[0][1],
                        name=scn.name if scn.name.endswith(suffix) else f"{scn.name}{suffix}")
    if duration_s is not None:
        scn = scn.with_(max_duration_s=float(duration_s))
    why = budget_refusal(scn.max_duration_s, scn.dt_control_s)
    if why is not None:
        raise ConfigError(scn.file, "--duration" if duration_s is not None else "scenario.max_duration_s", why)
    return scn


def add_variant_arguments(p) -> None:
    """Command-line options of a run's variant, shared by batch, the SIL launcher and its nodes."""
    p.add_argument("--identification", choices=IDENTIFICATION, default=None,
                   help="detect: FDIR identifies faults (default); oracle: TEST MODE, the plant's fault log "
                        "reaches FDIR at the fault time (the paper's assumption)")
    p.add_argument("--no-initial-error", action="store_true",
                   help="the bank starts on the reference (the paper's set-up has a 5 deg initial error)")
    p.add_argument("--dt-control", type=argtypes.float_range(1e-3, 0.1), default=None, metavar="S",
                   help="control period [s] instead of the scenario's (e.g. 0.005: 200 Hz); a whole number "
                        "of the plant's integrator steps")


def variant_argv(a) -> list[str]:
    return ((["--identification", a.identification] if a.identification else [])
            + (["--no-initial-error"] if a.no_initial_error else [])
            + (["--dt-control", repr(a.dt_control)] if a.dt_control is not None else []))


def prepare_args(a) -> Scenario:
    """prepare() from parsed command-line arguments."""
    return prepare(a.scenario, a.ft_off, a.duration, a.identification, not a.no_initial_error,
                   getattr(a, "dt_control", None))


def end_reason_of(reason: str, duration_s: float | None) -> str:
    """The run's end reason from the plant's: its time limit reached is the requested
    ``duration`` when the command line asked for one (``--duration``), else the scenario's
    own time cap (``timeout``: the flight did not get to parachute deployment)."""
    return "duration" if duration_s is not None and reason == "timeout" else reason
