"""The event catalogue: every event the flight software (and the ground tools) can report,
declared once — numeric id, name, source, severity, typed arguments, message format,
throttle — as F´ declares a component's events. Call sites name their entry and pass its
arguments (``events.emit(t_s, EV.JET_FAILED_OFF, jet=3)``, common/events.py); everything
else is derived from here: the STATUSTEXT text, the ground console's filters, the Rerun
events table, docs/events.md and the events metadata file of the MAVLink events interface
(interfaces/event_metadata.py).

An entry's message is a Python format string over its argument names, rendered to at most
50 characters (one STATUSTEXT). An entry may have several forms (``messages``): the form
is the one whose fields are exactly the arguments given, e.g. a reconfiguration with or
without the thrust factor of a degraded jet. Argument types are those of the MAVLink events
protocol (libevents: integers, float, enums) plus TEXT, free text that only the STATUSTEXT
carries (an EVENT message carries numbers and enum values).

EVENT ids: the high 8 bits name the component (MAVLink component 1, namespace
"ellipsled"), the low 24 bits the entry and its form: ``id * 10 + form``.
"""
from __future__ import annotations

import re
import string
import struct
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Mapping

from interfaces.codec import REJECT_REASONS
from interfaces.vocabulary import _enum as dialect_enum
from interfaces.vocabulary import FAULT_KINDS, HEALTH_NAMES, N_JETS, Mode, Severity

STATUSTEXT_LEN = 50          # characters of one MAVLink STATUSTEXT: a rendered message's limit
ARGS_LEN = 40                # bytes of EVENT.arguments
COMPONENT_ID = 1             # MAVLink component (MAV_COMP_ID_AUTOPILOT1): the EVENT ids' high byte
NAMESPACE = "ellipsled"      # libevents namespace of that component
FORMS = 10                   # EVENT sub-id = entry id * FORMS + form
SOURCES = ("modes", "monitor", "driver", "fdir", "executive", "allocator", "guidance", "ground", "link", "bridge")
TEXT_MARK = "…"              # what a TEXT argument shows in the events metadata (STATUSTEXT has it)

ERROR, WARNING, NOTICE, INFO = Severity.ERROR, Severity.WARNING, Severity.NOTICE, Severity.INFO


# --------------------------------------------------------------------------- argument types
@dataclass(frozen=True)
class ArgType:
    """A libevents argument type: a basic type ("uint8_t", ..., "float"), an enum (``labels``:
    value -> the text it shows, over an unsigned basic type), or TEXT (no wire type)."""
    name: str
    code: str                                   # struct code, little-endian; "" for TEXT
    labels: Mapping[int, str] | None = None
    description: str = ""

    @property
    def is_text(self) -> bool:
        return not self.code

    @property
    def is_enum(self) -> bool:
        return self.labels is not None

    @property
    def base(self) -> str:
        """The libevents basic type the value travels as."""
        return {"B": "uint8_t", "H": "uint16_t"}[self.code] if self.is_enum else self.name

    def entry_name(self, value: int) -> str:
        """libevents enum entry name of ``value``: its label in lower case and underscores."""
        name = re.sub(r"[^a-z0-9]+", "_", self.labels[value].lower()).strip("_")
        return name if name[:1].isalpha() else f"none{name}"

    def code_of(self, label: str) -> int:
        """The value of an enum's label (KeyError for none)."""
        return next(k for k, v in self.labels.items() if v == label)

    def value(self, v):
        """``v`` as the renderer formats it: the label of an enum, a Python int or float."""
        if self.is_text:
            return str(v)
        if self.is_enum:
            return self.labels[int(v)]
        return float(v) if self.code == "f" else int(v)


U8, U16, U32, I64 = ArgType("uint8_t", "B"), ArgType("uint16_t", "H"), ArgType("uint32_t", "I"), ArgType("int64_t", "q")
F32 = ArgType("float", "f")
TEXT = ArgType("text", "")


def enum_type(name: str, labels: Mapping[int, str], description: str) -> ArgType:
    return ArgType(name, "B" if max(labels) < 256 else "H", MappingProxyType(dict(labels)), description)


MODE = enum_type("mode_t", {int(m): m.name for m in Mode}, "Flight-software mode")
HEALTH = enum_type("jet_health_t", {c: n.upper() for c, n in HEALTH_NAMES.items()},
                   "Health of one jet (ELLIPSLED_JET_HEALTH): its state word")
JETS = enum_type("jets_t", {0: "ALL JETS", **{j: f"JET {j}" for j in range(1, N_JETS + 1)}}, "A jet, or 0: all jets")
FAULT = enum_type("fault_kind_t", {code: kind.upper() for kind, code in FAULT_KINDS.items()},
                  "Kind of a fault injected into the plant (MAVLink FAILURE_TYPE): the state word it sets")
REVERSAL_RULE = enum_type("reversal_rule_t", {v: k for k, v in dialect_enum("ELLIPSLED_REVERSAL_RULE").items()
                                              if v}, "Rule of the lateral logic that made a bank reversal")
# the SENSORS record's five vectors, in its order (fsw/monitors.py checks them in that order)
SENSOR_VECTOR = enum_type("sensor_vector_t", dict(enumerate(("OMEGA", "SIGMA", "R", "V", "ACCEL"))),
                          "A vector of the SENSORS record")
INHIBIT = enum_type("inhibit_t", {0: "INHIBIT CLEARED", 1: "INHIBITED"}, "Ground inhibit mask set or cleared")
OVERRIDE = enum_type("override_t", {0: "", 1: " (GND OVERRIDE HOLDS)"}, "Whether a ground override keeps the jet")
ON_OFF = enum_type("on_off_t", {0: "OFF", 1: "ON"}, "Off or on")
OVERRUN = enum_type("overrun_t", {0: "SKIPPED: PREVIOUS STILL RUNNING", 1: "OVERRUN: COMMAND KEPT"},
                    "What a late guidance cycle did")
# interfaces/records.py DEPLOY_* codes (FSW_STATE.deploy)
DEPLOY_RULE = enum_type("deploy_rule_t", {1: "RANGE TO GO USED UP", 2: "AT MACH", 3: "AT BOX EDGE",
                                           4: "AT ALTITUDE FLOOR"},
                        "Rule of the deploy trigger that commanded the parachute")
ENUMS = (MODE, HEALTH, JETS, FAULT, REVERSAL_RULE, SENSOR_VECTOR, INHIBIT, OVERRIDE, ON_OFF, OVERRUN, DEPLOY_RULE)


# --------------------------------------------------------------------------- entries
@dataclass(frozen=True)
class Form:
    """One message of an entry: its fields in order (name, format spec) and its index."""
    index: int
    message: str
    fields: tuple[tuple[str, str], ...]


@dataclass(frozen=True, eq=False)
class EventDef:
    """One catalogue entry. ``name`` is the stable code (the attribute name of ``EV`` in
    lower case); ``throttle_s`` None: every occurrence is told; else occurrences closer than
    that are held and told as one summary (common/events.py EventLog)."""
    id: int
    source: str
    severity: Severity
    messages: tuple[str, ...]
    doc: str
    args: Mapping[str, ArgType]
    throttle_s: float | None = None
    name: str = ""
    forms: tuple[Form, ...] = field(default=(), repr=False)

    def __set_name__(self, owner, attr: str) -> None:
        if not self.name:
            object.__setattr__(self, "name", attr.lower())

    def form(self, given) -> Form:
        """The form whose fields are exactly the argument names ``given``."""
        want = set(given)
        for f in self.forms:
            if {n for n, _ in f.fields} == want:
                return f
        raise TypeError(f"event {self.name}: arguments {sorted(want)} match none of its messages "
                        f"({'; '.join(m for m in self.messages)})")

    def render(self, args: Mapping) -> tuple[Form, str]:
        """(the form, the text) of one occurrence: at most STATUSTEXT_LEN characters."""
        f = self.form(args)
        text = f.message.format_map({n: self.args[n].value(v) for n, v in args.items()})
        return f, text[:STATUSTEXT_LEN]

    def event_id(self, form: int = 0) -> int:
        """The MAVLink EVENT id of one form."""
        return COMPONENT_ID << 24 | (self.id * FORMS + form)

    def pack(self, form: Form, args: Mapping) -> bytes:
        """EVENT.arguments of one occurrence: the form's non-TEXT arguments in declaration
        order, little-endian, zero-padded to ARGS_LEN bytes."""
        out = b"".join(struct.pack("<" + t.code, int(args[n]) if t.code != "f" else float(args[n]))
                       for n, t in self.wire_args(form))
        return out.ljust(ARGS_LEN, b"\0")

    def wire_args(self, form: Form) -> list[tuple[str, ArgType]]:
        """The arguments an EVENT of ``form`` carries, in declaration order."""
        used = {n for n, _ in form.fields}
        return [(n, t) for n, t in self.args.items() if n in used and not t.is_text]


def _ev(id: int, source: str, severity: Severity, messages, doc: str, throttle_s: float | None = None,
        name: str = "", **args: ArgType) -> EventDef:
    msgs = (messages,) if isinstance(messages, str) else tuple(messages)
    forms = tuple(Form(i, m, tuple((fname, spec) for _, fname, spec, _ in string.Formatter().parse(m)
                                   if fname is not None)) for i, m in enumerate(msgs))
    return EventDef(id, source, severity, msgs, doc, MappingProxyType(args), throttle_s, name, forms)


REFUSAL_INTERVAL_S = 60.0    # the ground link's refusals: told at once, then summarised once a minute


class EV:
    """The catalogue, by name (``EV.JET_FAILED_OFF``); ids grouped by source."""
    # modes (fsw/modes.py)
    MODE_CHANGE = _ev(101, "modes", NOTICE, "MODE {current}->{target} ({reason})", "The mode changed.",
                      current=MODE, target=MODE, reason=TEXT)
    MODE_REFUSED = _ev(102, "modes", WARNING, ("MODE {request:.12} UNKNOWN: REFUSED", "MODE {current}->{target} REFUSED"),
                       "A mode request was refused: no such mode, or a transition not allowed.",
                       request=TEXT, current=MODE, target=MODE)
    # sensor-frame monitor (fsw/monitors.py)
    FRAME_FORMAT = _ev(201, "monitor", WARNING, "SENSOR FRAME BAD FORMAT: REJECTED",
                       "A sensor frame that is not a SENSORS record was rejected.", 1.0)
    FRAME_RANGE = _ev(202, "monitor", WARNING, ("SENSOR FRAME BAD K {k}", "SENSOR {vector} OUT OF RANGE {value:.4g}"),
                      "A sensor frame with a negative step index or an incredible vector was rejected.", 1.0,
                      k=I64, vector=SENSOR_VECTOR, value=F32)
    FRAME_NONFINITE = _ev(203, "monitor", WARNING, "SENSOR FRAME NON-FINITE {vector}",
                          "A sensor frame with a non-finite vector was rejected.", 1.0, vector=SENSOR_VECTOR)
    FRAME_DUPLICATE = _ev(204, "monitor", WARNING, "SENSOR FRAME K {k} DUPLICATE",
                          "A sensor frame repeating the last step index was rejected.", 1.0, k=I64)
    FRAME_OUT_OF_ORDER = _ev(205, "monitor", WARNING, "SENSOR FRAME K {k} OUT OF ORDER",
                             "A sensor frame older than the last accepted was rejected.", 1.0, k=I64)
    SENSORS_STALE = _ev(206, "monitor", ERROR, "SENSORS STALE ({periods} PERIODS): JETS HELD OFF",
                        "No fresh sensor frame for fdir.stale_s: the jets are held off.", periods=U32)
    SENSORS_RECOVERED = _ev(207, "monitor", NOTICE, "SENSORS RECOVERED", "Fresh sensor frames again after staleness.")
    CHAMBER_NONFINITE = _ev(208, "monitor", WARNING, "CHAMBER NON-FINITE JET {jet}",
                            "A chamber-pressure sample was not finite; FDIR ignores it.", 1.0, jet=U8)
    CHAMBER_RANGE = _ev(209, "monitor", WARNING, "CHAMBER OUT OF RANGE JET {jet}",
                        "A chamber-pressure sample was outside its credible range; FDIR ignores it.", 1.0, jet=U8)
    # jet driver (fsw/jetdriver.py)
    JETS_ARMED = _ev(301, "driver", NOTICE, "JETS ARMED", "The jet driver was armed.")
    JETS_DISARMED = _ev(302, "driver", NOTICE, "JETS DISARMED", "The jet driver was disarmed.")
    JET_INHIBIT = _ev(303, "driver", NOTICE, "{jets} {inhibit}", "The ground set or cleared the inhibit mask of jets.",
                      jets=JETS, inhibit=INHIBIT)
    # FDIR (fsw/fdir.py, fsw/commands.py)
    FDIR_ORACLE = _ev(401, "fdir", WARNING, "TEST MODE: FDIR ORACLE IDENTIFICATION",
                      "FDIR takes the plant's faults as given (a test mode), not from its jet monitor.")
    FDIR_DELAY = _ev(402, "fdir", NOTICE, "FDIR DELAY {delay_s:.2f} S",
                     "The isolation-to-reconfiguration delay was set.", delay_s=F32)
    FDIR_CHAMBER_SKIP = _ev(403, "fdir", WARNING, "FDIR SKIPS NON-FINITE CHAMBER JET {jet} (x{count})",
                            "The jet monitor skipped non-finite chamber samples (first jet, how many).", 1.0,
                            jet=U8, count=U32)
    JET_FAILED_OFF = _ev(404, "fdir", ERROR, "JET {jet} FAILED_OFF", "The jet monitor isolated a jet that does not fire.",
                         jet=U8)
    JET_STUCK_ON = _ev(405, "fdir", ERROR, "JET {jet} STUCK_ON", "The jet monitor isolated a jet that fires uncommanded.",
                       jet=U8)
    JET_DEGRADED = _ev(406, "fdir", WARNING, "JET {jet} DEGRADED ETA {eta:.2f}",
                       "The jet monitor isolated a jet giving less thrust (its estimated factor).", jet=U8, eta=F32)
    FDIR_RECONFIG = _ev(407, "fdir", NOTICE, ("RECONFIG JET {jet} {health}{override}",
                                         "RECONFIG JET {jet} {health} ETA {eta:.2f}{override}"),
                        "An isolation took effect after the reconfiguration delay.",
                        jet=U8, health=HEALTH, eta=F32, override=OVERRIDE)
    FDIR_OVERRIDE = _ev(408, "fdir", NOTICE, ("GND MARK JET {jet} {health}", "GND MARK JET {jet} {health} ETA {eta:.2f}"),
                        "The ground marked a jet's health (held until cleared).", jet=U8, health=HEALTH, eta=F32)
    FDIR_CLEAR = _ev(409, "fdir", NOTICE, "GND CLEAR {jets}",
                     "The ground cleared FDIR's latch, pending reconfiguration and override of jets.", jets=JETS)
    UNEXPLAINED_TORQUE = _ev(410, "fdir", WARNING, "UNEXPLAINED TORQUE {torque_Nm:.0f} NM",
                             "The angular-acceleration residual stayed above its limit.", 1.0, torque_Nm=F32)
    # executive (fsw/executive.py)
    TASK_ERROR = _ev(501, "executive", ERROR, "task {task}: {error}", "A task raised; the executive went on.", 1.0,
                     task=TEXT, error=TEXT)
    RELEASE_MISSED = _ev(502, "executive", WARNING, "{count} release(s) missed before tick {tick}",
                         "The clock skipped releases (the loop was late by whole periods).", 1.0, count=U32, tick=U32)
    CYCLE_SLIP = _ev(503, "executive", WARNING, "slip k={tick} {took_ms:.1f}>{deadline_ms:.0f}ms {task} {task_ms:.1f}",
                     "A cycle ended past its deadline (its longest task named).", 1.0,
                     tick=U32, took_ms=F32, deadline_ms=F32, task=TEXT, task_ms=F32)
    # allocator (fsw/flightsoftware.py)
    RECONFIGURED = _ev(601, "allocator", NOTICE, "ALLOCATOR RECONFIGURED ({rebuild_ms:.1f} ms)",
                       "The allocator took new tables for a new jet health.", rebuild_ms=F32)
    ALLOC_DEGRADED = _ev(602, "allocator", WARNING, "ALLOCATION DEGRADED (infeasible)",
                         "The allocation problem was infeasible; the best effort was sent.", 1.0)
    ALLOC_SHORT = _ev(603, "allocator", WARNING, "ALLOCATION SHORT ON BANK AXIS",
                      "The allocated torque fell short of the demand on the bank axis.", 1.0)
    ALLOC_LP_FALLBACK = _ev(604, "allocator", WARNING, "DUTY-CYCLE LP SOLVED BY FALLBACK",
                            "The duty-cycle LP's compiled solver failed; HiGHS solved the cycle's LP.", 1.0)
    # guidance (fsw/authority.py, fsw/guidance/npc.py, their background jobs: fsw/jobs.py)
    CONTROLLABILITY = _ev(701, "guidance", NOTICE, "AUTH +{auth_pos:.2f}/-{auth_neg:.2f} DEG/S2 BIAS {bias_Nm:.0f}NM "
                                              "TRIM {trim}DEG",
                          "The controllability LP's answer: bank authority each way [deg/s2], stuck-on bias, trim.",
                          auth_pos=F32, auth_neg=F32, bias_Nm=F32, trim=TEXT)
    NOT_CONTROLLABLE = _ev(702, "guidance", WARNING, "NOT CONTROLLABLE: {reason}",
                           "The jets left cannot control the bank (the reason).", reason=TEXT)
    AUTHORITY_LOW = _ev(703, "guidance", WARNING, "BANK AUTH {auth:.2f} DEG/S2: REF KEPT AT NEED",
                        "The bank authority is below what the schedule needs; the reference keeps its pace.", auth=F32)
    REFERENCE_RESHAPED = _ev(704, "guidance", NOTICE, "REFERENCE ACCEL LIMIT {limit:.2f} DEG/S2",
                             "The bank reference was re-planned to a new acceleration limit.", limit=F32)
    BANK_REVERSAL = _ev(705, "guidance", INFO, "BANK REVERSAL ({rule}) DPSI {dpsi_deg:+.1f} DEG",
                        "The lateral logic reversed the bank (its rule, the heading error).",
                        rule=REVERSAL_RULE, dpsi_deg=F32)
    GUIDANCE_OVERRUN = _ev(706, "guidance", WARNING, "GUIDANCE CYCLE {what}",
                           "A guidance cycle was skipped or answered late; the command in force stays.", 1.0,
                           what=OVERRUN)
    GUIDANCE_FAULT = _ev(707, "guidance", WARNING, "GUIDANCE FAULT: {error}",
                         "The correction raised (the exception); the previous command stays.", 1.0, error=TEXT)
    DEPLOY_ALT_FLOOR = _ev(708, "guidance", NOTICE, "DEPLOY ALT FLOOR: RANGE TRADED {miss_km:+.1f} KM",
                           "The deploy-altitude floor now limits the correction (range traded for altitude).",
                           miss_km=F32)
    REVERSAL_WAY = _ev(709, "guidance", INFO, "REVERSAL TURNED ROUND: MISS {miss_km:+.1f} KM",
                       "The reversal under way turned round: no range solution the way it went.", miss_km=F32)
    GUIDANCE_NO_ROOT = _ev(710, "guidance", NOTICE, "NO RANGE SOLUTION: MISS {miss_km:+.1f} KM",
                           "The corrector found no bank reaching the target; it flies the better bound.", 1.0,
                           miss_km=F32)
    NPC_PARAM = _ev(711, "guidance", INFO, "GUIDANCE {param} {value:g}",
                    "A guidance parameter took effect (between corrections).", param=TEXT, value=F32)
    CONTROLLABILITY_OVERRUN = _ev(712, "guidance", WARNING, "CONTROLLABILITY CYCLE {what}",
                                  "A controllability LP was skipped or answered late; the last answer stays.", 1.0,
                                  what=OVERRUN)
    CONTROLLABILITY_FAULT = _ev(713, "guidance", WARNING, "CONTROLLABILITY FAULT: {error}",
                                "The controllability LP raised; the last answer stays.", 1.0, error=TEXT)
    DEPLOY_COMMAND = _ev(714, "guidance", NOTICE, "DEPLOY {rule} M{mach:.2f} H{h_km:.1f} RTG{rtg_km:+.1f}",
                         "The deploy trigger commanded the parachute (its rule; Mach, altitude and range to go "
                         "then). AT BOX EDGE: the trigger's rule did not fire inside the deploy box; AT ALTITUDE FLOOR: "
                         "range to go traded for the deploy altitude.",
                         rule=DEPLOY_RULE, mach=F32, h_km=F32, rtg_km=F32)
    # ground commands (fsw/commands.py, fsw/groundlink/commands.py)
    FAULT_TOLERANCE = _ev(801, "ground", NOTICE, "GND FAULT TOLERANCE {state}",
                          "The ground switched the allocator's fault tolerance.", state=ON_OFF)
    INJECT = _ev(802, "link", NOTICE, ("GND INJECT {jets} {kind}", "GND INJECT {jets} {kind} ETA {eta:.2f}"),
                 "The ground injected a fault into the plant (SIL).", jets=JETS, kind=FAULT, eta=F32)
    # ground link (fsw/groundlink/link.py, ellipsled/sil/fsw_node.py)
    LINK_FLOOD = _ev(851, "link", WARNING, "link flooded: {dropped} datagrams dropped",
                     "The kernel dropped datagrams for the vehicle's port (a flood).", 1.0, dropped=U32)
    LINK_REFUSED = _ev(852, "link", WARNING, "{detail}",
                       "The ground link refused frames or requests (the last, + how many were held).",
                       REFUSAL_INTERVAL_S, detail=TEXT)
    PARAM_UNKNOWN = _ev(853, "link", WARNING, "{detail}", "A signed parameter request named no parameter.", detail=TEXT)
    PARAM_REFUSED = _ev(854, "link", WARNING, "{detail}", "A signed parameter set was refused (the reason).", detail=TEXT)
    CMD_REFUSED = _ev(855, "link", WARNING, "{detail}", "A signed command was not accepted (the reason).", detail=TEXT)
    NEW_SENSOR_SOURCE = _ev(856, "link", NOTICE, "NEW SENSOR SOURCE",
                            "Sensor frames come from a new plant process (a restart).")
    MAVLINK_BIND = _ev(857, "link", ERROR, "GROUND LINK OFF: PORT IN USE",
                       "The ground link could not bind its port; the vehicle flies without it.")
    # ground tools (gse/viz/bridge.py)
    BAD_PAYLOAD = _ev(901, "bridge", WARNING, "{reason}: {detail}", "The viewer bridge rejected a payload.", 1.0,
                      reason=TEXT, detail=TEXT)


def _sensor_rejects() -> None:
    """One entry per rejection reason of the codec (interfaces/codec.py REJECT_REASONS): a
    sensor payload the FSW process refused, throttled per reason."""
    for i, reason in enumerate(REJECT_REASONS):
        setattr(EV, f"RX_{reason.upper()}", _ev(860 + i, "link", WARNING, f"SENSOR PAYLOAD REJECTED: {reason}",
                                                f"A sensor payload was rejected by the codec: {reason}.", 1.0,
                                                name=f"rx_{reason}"))


_sensor_rejects()

CATALOGUE: tuple[EventDef, ...] = tuple(sorted((v for v in vars(EV).values() if isinstance(v, EventDef)),
                                               key=lambda e: e.id))
BY_NAME: Mapping[str, EventDef] = MappingProxyType({e.name: e for e in CATALOGUE})
BY_ID: Mapping[int, EventDef] = MappingProxyType({e.id: e for e in CATALOGUE})


def by_event_id(event_id: int) -> tuple[EventDef, Form] | None:
    """(entry, form) of a MAVLink EVENT id, or None if it is not this catalogue's."""
    if event_id >> 24 != COMPONENT_ID:
        return None
    e = BY_ID.get((event_id & 0xFFFFFF) // FORMS)
    f = (event_id & 0xFFFFFF) % FORMS
    return (e, e.forms[f]) if e is not None and f < len(e.forms) else None


def sample_value(t: ArgType):
    """A value of type ``t`` as wide as it renders (the longest label, a long number)."""
    if t.is_enum:
        return max(t.labels, key=lambda v: len(t.labels[v]))
    return {"text": "x" * STATUSTEXT_LEN, "float": -12345.678}.get(t.name, 255 if t.code == "B" else 99999)


def check(catalogue=CATALOGUE) -> list[str]:
    """What is wrong with the catalogue (empty: nothing): unique ids and names, known
    sources, fields that are declared arguments, each argument used, distinct forms, the
    literal text and the EVENT arguments within their limits."""
    bad = []
    for what, key in (("id", lambda e: e.id), ("name", lambda e: e.name)):
        seen: dict = {}
        for e in catalogue:
            if key(e) in seen:
                bad.append(f"{e.name}: {what} {key(e)} also used by {seen[key(e)]}")
            seen[key(e)] = e.name
    for e in catalogue:
        if e.source not in SOURCES:
            bad.append(f"{e.name}: source {e.source!r} not one of {SOURCES}")
        if not (0 < e.id and e.id * FORMS + len(e.forms) < 1 << 24) or len(e.forms) > FORMS:
            bad.append(f"{e.name}: id {e.id} or {len(e.forms)} forms outside the EVENT id's 24 bits")
        used = set()
        for f in e.forms:
            names = [n for n, _ in f.fields]
            used |= set(names)
            if set(names) - set(e.args) or len(set(names)) != len(names):
                bad.append(f"{e.name}: message {f.message!r} names {names}, arguments are {list(e.args)}")
                continue
            if len(re.sub(r"\{[^}]*\}", "", f.message)) > STATUSTEXT_LEN:
                bad.append(f"{e.name}: message {f.message!r} longer than {STATUSTEXT_LEN} characters")
            if sum(struct.calcsize("<" + t.code) for _, t in e.wire_args(f)) > ARGS_LEN:
                bad.append(f"{e.name}: arguments of {f.message!r} exceed {ARGS_LEN} bytes")
            try:
                e.render({n: sample_value(e.args[n]) for n in names})
            except (ValueError, KeyError, TypeError) as x:
                bad.append(f"{e.name}: {f.message!r} does not render: {x}")
        if set(e.args) - used:
            bad.append(f"{e.name}: arguments {sorted(set(e.args) - used)} in no message")
        if len({frozenset(n for n, _ in f.fields) for f in e.forms}) != len(e.forms):
            bad.append(f"{e.name}: two messages take the same arguments")
    return bad


_problems = check()
if _problems:
    raise ImportError("interfaces/event_catalogue.py: " + "; ".join(_problems))


# --------------------------------------------------------------------------- reading texts back
_SUPPRESSED = r"(?: \(\+\d+ suppressed\))?"


def _field_pattern(t: ArgType) -> str:
    if t.is_enum:
        return "(?:" + "|".join(re.escape(s) for s in sorted(t.labels.values(), key=len, reverse=True)) + ")"
    if t.is_text:
        return ".*?"
    return r"[-+]?(?:\d+\.?\d*(?:e[-+]?\d+)?|nan|inf)"


def _form_pattern(e: EventDef, f: Form) -> re.Pattern | None:
    """A regular expression matching what ``f`` renders, or None when its text is free text
    but for punctuation (it could be anything)."""
    parts, literal = [], ""
    for lit, fname, _, _ in string.Formatter().parse(f.message):
        parts.append(re.escape(lit))
        literal += lit
        if fname is not None:
            parts.append(_field_pattern(e.args[fname]))
    if not re.search(r"[A-Za-z0-9]", literal):
        return None
    return re.compile("".join(parts) + _SUPPRESSED + r"\Z", re.DOTALL)


# more literal text first: the most specific form wins
_PATTERNS = sorted(((p, e, len(re.sub(r"\{[^}]*\}", "", f.message))) for e in CATALOGUE for f in e.forms
                    for p in [_form_pattern(e, f)] if p is not None), key=lambda x: -x[2])
# a text cut at STATUSTEXT_LEN: known by the literal start of a message that can be that long
_HEADS = sorted(((f.message.split("{", 1)[0], e) for e in CATALOGUE for f in e.forms
                 if f.message.split("{", 1)[0]
                 and len(e.render({n: sample_value(e.args[n]) for n, _ in f.fields})[1]) >= STATUSTEXT_LEN),
                key=lambda x: -len(x[0]))


def identify(text: str) -> EventDef | None:
    """The entry whose message renders ``text`` (a STATUSTEXT, maybe cut at STATUSTEXT_LEN),
    or None (an entry whose message is all free text, or no entry of this catalogue)."""
    for p, e, _ in _PATTERNS:
        if p.match(text):
            return e
    if len(text) >= STATUSTEXT_LEN:
        whole = re.sub(r" \(\+\d*(?: [a-z]*\)?)?\Z", "", text)      # the cut was in a summary's count
        for p, e, _ in _PATTERNS:
            if whole != text and p.match(whole):
                return e
        for head, e in _HEADS:
            if text.startswith(head):
                return e
    return None


__all__ = ["EV", "EventDef", "ArgType", "Form", "CATALOGUE", "BY_NAME", "BY_ID", "ENUMS", "SOURCES", "STATUSTEXT_LEN",
           "COMPONENT_ID", "NAMESPACE", "TEXT_MARK", "by_event_id", "identify", "check",
           "U8", "U16", "U32", "I64", "F32", "TEXT"]
