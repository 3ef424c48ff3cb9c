"""The ground console (``ellipsled gse console``): a Textual terminal UI over a GroundClient.

Shows: link status (vehicle heartbeat age, rx/tx message rates, rejections, mode, armed,
MAV_STATE), entry state (altitude, speed, gamma, Mach, qbar, alpha, beta), bank vs
reference and the error, position (latitude, longitude, altitude of GLOBAL_POSITION_INT),
guidance (mode, range to go, predicted deploy miss and its downrange/crossrange split,
bank command, reversals, the controllability LP's bank authority: ELLIPSLED_GUIDANCE_STATUS,
"-" where the vehicle says "not available"), the 18-jet grid (commanded, firing, health),
loop timing and allocator figures, the events (STATUSTEXT with severity) and the
acknowledgements.

Commands from the command line at the bottom (the language of gse/commands.py USAGE, e.g.
"inject 17 failed_off", "mark 3 degraded 0.5", "param set C_LAMBDA_RADPS 1.2") or keys, when
the command line is not focused (Escape leaves it, ":" enters it):
  i inject...  c clear...  k mark...  p param set...   (prefill the command line)
  a arm/disarm toggle   f fault tolerance toggle   1 STANDBY  2 ENTRY  3 SAFE   q quit
Commands go out without blocking the UI; their ACK (or TIMEOUT after the retries)
appears in the acknowledgements panel.

The events panel shows each STATUSTEXT with its severity and its source, read back to its
entry of the event catalogue (interfaces/event_catalogue.py). ``events WORD...`` on the
command line filters it, with the catalogue's words: a severity ("events warning": that and
worse), sources ("events fdir driver") and event names ("events jet_failed_off"), any
unambiguous prefix; ``events all`` shows everything again, ``events`` says what is shown.

The same screens watch without commanding: over a client without the key (``--view-only``:
telemetry shown unverified, nothing sent) or over a recorded .tlog (``--replay``,
gse/replay.py); the top line says which, and a command is answered "not sent".
"""
from __future__ import annotations

import math
import time

from rich.table import Table
from rich.text import Text
from textual.app import App, ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.css.query import NoMatches
from textual.widgets import Footer, Input, RichLog, Static

from interfaces.event_catalogue import BY_NAME, SOURCES, identify
from interfaces.mavlink import dialect as mav
from interfaces.vocabulary import N_JETS, JetState, Mode, Severity

from .client import GroundClient, PendingCommand, result_name
from .commands import parse_line

# how each jet state and severity is drawn (the names and codes: interfaces/vocabulary.py)
HEALTH_STYLE = {JetState.NOMINAL: "green", JetState.FAILED_OFF: "bold red", JetState.STUCK_ON: "bold magenta",
                JetState.DEGRADED: "yellow", JetState.INHIBITED: "cyan"}
SEVERITY_STYLE = {Severity.EMERGENCY: "bold white on red", Severity.ALERT: "bold red", Severity.CRITICAL: "bold red",
                  Severity.ERROR: "red", Severity.WARNING: "yellow", Severity.NOTICE: "cyan", Severity.INFO: "white",
                  Severity.DEBUG: "dim"}


def _lost(c) -> tuple[str, str]:
    """Datagrams the kernel dropped before the console read them (its socket full), shown
    when there are any: telemetry and events this console never saw."""
    n = getattr(c, "stats", {}).get("rx_kernel_drops", 0)
    return (f"  LOST {n} datagrams", "bold red") if n else ("", "")


def _mode_name(code: int) -> str:
    return Mode(code).name if code in Mode._value2member_map_ else str(code)


def _severity_name(code: int) -> str:
    return Severity(code).name if code in Severity._value2member_map_ else str(code)


class EventFilter:
    """Which events the panel shows: at least ``severity`` (None: any), and, when sources or
    names are chosen, only the events of those (an event the catalogue does not know then
    not at all). Words: the catalogue's severities, sources and event names."""

    WORDS = {**{s.name.lower(): ("severity", s) for s in Severity}, **{s: ("source", s) for s in SOURCES},
             **{n: ("name", n) for n in BY_NAME}}

    def __init__(self, severity: Severity | None = None, sources=(), names=()):
        self.severity, self.sources, self.names = severity, frozenset(sources), frozenset(names)

    @classmethod
    def parse(cls, words: list[str]) -> "EventFilter":
        """The filter ``words`` say ("all" or none: everything); ValueError names a bad word."""
        severity, sources, names = None, set(), set()
        for w in (w.lower() for w in words):
            if w == "all":
                continue
            hits = [w] if w in cls.WORDS else [k for k in cls.WORDS if k.startswith(w)]
            if len(hits) != 1:
                raise ValueError(f"events: {w!r} is {'ambiguous' if hits else 'not a severity, source or event'}"
                                 + (f" ({', '.join(sorted(hits)[:6])})" if hits else ""))
            kind, value = cls.WORDS[hits[0]]
            if kind == "severity":
                severity = value
            else:
                (sources if kind == "source" else names).add(value)
        return cls(severity, sources, names)

    def shows(self, severity: int, text: str) -> bool:
        if self.severity is not None and severity > self.severity:
            return False
        if not (self.sources or self.names):
            return True
        e = identify(text)
        return e is not None and (e.source in self.sources or e.name in self.names)

    def __str__(self) -> str:
        parts = ([f"{self.severity.name.lower()}+"] if self.severity is not None else []) \
            + sorted(self.sources) + sorted(self.names)
        return ", ".join(parts) or "all"


def _deg(x) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{math.degrees(x):8.2f}°"


def _state_name(code: int) -> str:
    e = mav.enums["MAV_STATE"].get(code)
    return e.name.removeprefix("MAV_STATE_") if e is not None else str(code)


class GroundConsole(App):
    """The console; ``client`` is a GroundClient the app polls (never blocks on it)."""

    CSS = """
    #top { height: 1; }
    #main { height: 1fr; }
    #left { width: 46; }
    #guidance { height: auto; max-height: 12; }
    #right { width: 1fr; }
    .panel { border: round $primary; padding: 0 1; }
    #events { height: 1fr; border: round $primary; }
    #acks { height: 8; border: round $primary; }
    #cmdline { dock: bottom; }
    """
    AUTO_FOCUS = None           # keys act until ":" enters the command line
    BINDINGS = [
        Binding("q", "quit", "quit"),
        Binding("colon", "focus_cmd", "command line"),
        Binding("escape", "blur_cmd", "leave command line", show=False),
        Binding("i", "prefill('inject ')", "inject"),
        Binding("c", "prefill('clear ')", "clear"),
        Binding("k", "prefill('mark ')", "mark"),
        Binding("p", "prefill('param set ')", "param"),
        # keys that change the vehicle's state only write their command on the command line:
        # Enter sends it. A key pressed while the command line is not yet focused (typing
        # fast after ':') then costs nothing, and an operator sees what will go out
        Binding("a", "toggle_arm", "arm/disarm"),
        Binding("f", "toggle_ft", "fault tol."),
        Binding("1", "prefill('mode standby')", "STANDBY"),
        Binding("2", "prefill('mode entry')", "ENTRY"),
        Binding("3", "prefill('mode safe')", "SAFE"),
    ]

    def __init__(self, client: GroundClient, *, timeout_s: float = 1.0, retries: int = 3,
                 poll_s: float = 0.05, refresh_s: float = 0.2, heartbeat_s: float = 1.0):
        super().__init__()
        self.client = client
        self.timeout_s = timeout_s
        self.retries = retries
        self.poll_s = poll_s
        self.refresh_s = refresh_s
        self.heartbeat_s = heartbeat_s
        self.inflight: list[tuple[str, PendingCommand]] = []
        self.ack_lines: list[str] = []      # what the acknowledgements panel shows (newest last)
        self.ft_on = True
        self._events_shown = 0
        self.event_filter = EventFilter()
        self._last_hb = 0.0
        replay = getattr(client, "path", None)
        self.watch_only = (f"replay of {replay.name}" if replay is not None
                           else "view only: no signing key" if client.view_only else "")

    # ---------------------------------------------------------------- layout
    def compose(self) -> ComposeResult:
        yield Static(id="top")
        with Horizontal(id="main"):
            with Vertical(id="left"):
                yield Static(id="entry", classes="panel")
                yield Static(id="jets", classes="panel")
                yield Static(id="timing", classes="panel")
            with Vertical(id="right"):
                yield Static(id="guidance", classes="panel")
                yield RichLog(id="events", max_lines=500, markup=False)
                yield RichLog(id="acks", max_lines=100, markup=False, wrap=True, min_width=20)   # whole, wrapped
        yield Input(placeholder="command (e.g. inject 17 failed_off) - Enter to send, Esc to leave", id="cmdline")
        yield Footer()

    def on_mount(self) -> None:
        self.title = "ellipsled ground console" + (f" ({self.watch_only})" if self.watch_only else "")
        self.query_one("#events", RichLog).border_title = "events"
        self.query_one("#acks", RichLog).border_title = "acknowledgements"
        self.set_interval(self.poll_s, self._pump)
        self.set_interval(self.refresh_s, self.refresh_view)
        self.refresh_view()

    # ---------------------------------------------------------------- link pump
    def _pump(self) -> None:
        try:
            self._pump_link()
        except NoMatches:           # a timer that fires while the app shuts down
            pass

    def _pump_link(self) -> None:
        c = self.client
        now = time.monotonic()
        if now - self._last_hb >= self.heartbeat_s and not self.watch_only:
            c.send_heartbeat()
            self._last_hb = now
        c.poll(0.0)
        still = []
        for label, pc in self.inflight:
            if pc.done:
                self._ack_line(f"{label}: {result_name(pc.result)}")
            else:
                still.append((label, pc))
        self.inflight = still
        evs = list(c.state.events)
        new = c.state.events_total - self._events_shown
        self._write_events(evs[max(0, len(evs) - new):])
        self._events_shown = c.state.events_total

    def _write_events(self, evs) -> None:
        log = self.query_one("#events", RichLog)
        for e in evs:
            if self.event_filter.shows(e.severity, e.text):
                entry = identify(e.text)
                log.write(Text(f"{time.strftime('%H:%M:%S', time.localtime(e.t_unix_s))} "
                               f"{_severity_name(e.severity):<9} {entry.source if entry else '-':<9} {e.text}",
                               style=SEVERITY_STYLE.get(e.severity, "")))

    def set_event_filter(self, words: list[str]) -> None:
        """``events WORD...``: filter the events panel (and show it again from what is kept)."""
        if words:
            try:
                self.event_filter = EventFilter.parse(words)
            except ValueError as e:
                self._ack_line(f"! {e}")
                return
            self.query_one("#events", RichLog).clear()
            self._write_events(list(self.client.state.events))
        self.query_one("#events", RichLog).border_title = f"events ({self.event_filter})"
        self._ack_line(f"events shown: {self.event_filter}")

    def _ack_line(self, line: str) -> None:
        self.ack_lines.append(line)
        self.query_one("#acks", RichLog).write(line)

    # ---------------------------------------------------------------- commands
    def submit(self, text: str) -> None:
        """Run one command line (also what pressing Enter in the command line does)."""
        words = text.lstrip(":").split()
        if words[:1] == ["events"]:
            self.set_event_filter(words[1:])
            return
        try:
            req = parse_line(text.lstrip(":"))
        except ValueError as e:
            self._ack_line(f"! {e}")
            return
        self._send(req)

    def _send(self, req) -> None:
        if self.watch_only:
            self._ack_line(f"{req.label}: not sent ({self.watch_only})")
            return
        if self.client.vehicle_addr is None:
            self._ack_line(f"{req.label}: no vehicle yet (no telemetry received)")
            return
        if req.command == mav.ELLIPSLED_CMD_FAULT_TOLERANCE:
            self.ft_on = bool(req.params[0])
        pc = self.client.start(req, self.timeout_s, self.retries)
        if pc is not None:
            self.inflight.append((req.label, pc))
            self._ack_line(f"{req.label}: sent")
        else:
            self._ack_line(f"{req.label}: sent (answer in PARAM_VALUE)")

    def on_input_submitted(self, event: Input.Submitted) -> None:
        text = event.value.strip()
        event.input.value = ""
        if text:
            self.submit(text)

    def action_focus_cmd(self) -> None:
        self.query_one("#cmdline", Input).focus()

    def action_blur_cmd(self) -> None:
        self.set_focus(None)

    def action_prefill(self, text: str) -> None:
        inp = self.query_one("#cmdline", Input)
        inp.value = text
        inp.cursor_position = len(text)
        inp.focus()

    def action_toggle_arm(self) -> None:
        """The command line gets the opposite of the jets' state now (Enter sends it)."""
        hb = self.client.state.latest.get("HEARTBEAT")
        armed = bool(hb and hb.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)
        self.action_prefill("arm off" if armed else "arm on")

    def action_toggle_ft(self) -> None:
        self.action_prefill("ft off" if self.ft_on else "ft on")

    # ---------------------------------------------------------------- view
    def refresh_view(self) -> None:
        try:
            self._refresh_view()
        except NoMatches:           # a timer that fires while the app shuts down
            pass

    def _refresh_view(self) -> None:
        c = self.client
        st = c.state
        hb = st.latest.get("HEARTBEAT")
        age = c.link_age_s()
        if hb is None:
            top = Text(" no vehicle heartbeat yet", style="bold yellow")
        else:
            armed = "ARMED" if hb.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED else "disarmed"
            status = _state_name(hb.system_status)
            style = {"ACTIVE": "green", "CRITICAL": "bold red", "EMERGENCY": "bold white on red"}.get(status, "yellow")
            where = f"{c.vehicle_addr[0]}:{c.vehicle_addr[1]}" if c.vehicle_addr else "?"
            top = Text.assemble(
                (f" {_mode_name(hb.custom_mode)} ", "bold"), (f"{status} ", style),
                f"{armed}  link: hb {age:.1f}s ago  rx {c.rate_hz('rx'):.0f}/s  tx {c.rate_hz('tx'):.1f}/s  "
                f"rejected {c.rejected}  vehicle {where}", _lost(c))
        if self.watch_only:
            label = self.watch_only
            if hasattr(c, "duration_s"):
                label += f" x{c.speed:g} {c.clock() - c.records[0][0] * 1e-6:.0f}/{c.duration_s:.0f} s" \
                         + (" (end)" if c.done else "")
            top = Text.assemble((f" {label.upper()} ", "bold black on yellow"),
                                (" telemetry not verified " if c.view_only else ""), top)
        self.query_one("#top", Static).update(top)
        self.query_one("#entry", Static).update(self._entry_table())
        self.query_one("#guidance", Static).update(self._guidance_table())
        self.query_one("#jets", Static).update(self._jet_table())
        self.query_one("#timing", Static).update(self._timing_table())

    @staticmethod
    def _figures(title: str, present: bool) -> Table:
        """A two-column grid (bold name, right-aligned value); "-" when nothing arrived yet."""
        t = Table.grid(padding=(0, 1))
        t.add_column(style="bold")
        t.add_column(justify="right")
        if not present:
            t.add_row(title, "-")
        return t

    def _entry_table(self) -> Table:
        es = self.client.state.latest.get("ELLIPSLED_ENTRY_STATE")
        t = self._figures("entry state", es is not None)
        if es is None:
            return t
        err = math.remainder(es.bank - es.bank_ref, 2 * math.pi)
        t.add_row("altitude", f"{es.altitude / 1e3:8.2f} km")
        t.add_row("speed", f"{es.speed:8.1f} m/s")
        t.add_row("gamma", _deg(es.flight_path_angle))
        t.add_row("Mach / qbar", f"{es.mach:5.2f} / {es.qbar:7.0f} Pa")
        t.add_row("alpha / beta", f"{_deg(es.alpha)} {_deg(es.beta)}")
        t.add_row("bank", _deg(es.bank))
        t.add_row("bank ref", _deg(es.bank_ref))
        t.add_row(Text("bank error", style="bold"),
                  Text(_deg(err), style="bold red" if abs(err) > math.radians(10) else "bold green"))
        gp = self.client.state.latest.get("GLOBAL_POSITION_INT")
        if gp is not None:
            t.add_row("lat / lon", f"{gp.lat * 1e-7:8.4f}° {gp.lon * 1e-7:9.4f}°")
            t.add_row("alt (position)", f"{gp.alt * 1e-6:8.2f} km")
        return t

    def _guidance_table(self) -> Table:
        """ELLIPSLED_GUIDANCE_STATUS; a group whose flag is clear shows "-"."""
        g = self.client.state.latest.get("ELLIPSLED_GUIDANCE_STATUS")
        t = self._figures("guidance", g is not None)
        if g is None:
            return t

        def has(bit: int) -> bool:
            return bool(g.flags & bit)
        npc = g.mode == mav.ELLIPSLED_GUIDANCE_MODE_NPC
        t.add_row("guidance", "NPC" if npc else "PROFILE" if g.mode == mav.ELLIPSLED_GUIDANCE_MODE_PROFILE
                  else str(g.mode))
        t.add_row("range to go", f"{g.range_to_go / 1e3:8.1f} km" if has(mav.ELLIPSLED_GUIDANCE_FLAGS_TARGET) else "-")
        if has(mav.ELLIPSLED_GUIDANCE_FLAGS_PREDICTION):
            note = " NO ROOT" if has(mav.ELLIPSLED_GUIDANCE_FLAGS_NO_ROOT) else \
                " held" if has(mav.ELLIPSLED_GUIDANCE_FLAGS_FROZEN) else ""
            miss_style = "bold green" if g.predicted_miss < 1e3 else "yellow" if g.predicted_miss < 12.5e3 else "bold red"
            t.add_row(Text("pred. miss", style="bold"), Text(f"{g.predicted_miss / 1e3:6.2f} km{note}", style=miss_style))
            t.add_row("down / cross", f"{g.downrange_error / 1e3:+7.2f} {g.crossrange_error / 1e3:+7.2f} km")
            t.add_row("deploy alt / tgo", f"{g.predicted_alt / 1e3:6.2f} km {g.time_to_go:5.0f} s")
        else:
            t.add_row("pred. miss", "-")
        if npc:
            side = "R" if g.bank_sign > 0 else "L" if g.bank_sign < 0 else ""
            t.add_row("bank cmd", f"{_deg(g.bank_cmd)} {side}")
            last = ""
            if g.reversals:
                rule = {mav.ELLIPSLED_REVERSAL_RULE_CORRIDOR: "corridor",
                        mav.ELLIPSLED_REVERSAL_RULE_FINAL: "final"}.get(g.last_reversal_rule, "?")
                last = f", last {g.last_reversal_time:.0f} s {rule}"
            t.add_row("reversals", f"{g.reversals}{last}")
        if has(mav.ELLIPSLED_GUIDANCE_FLAGS_LP):
            ok = has(mav.ELLIPSLED_GUIDANCE_FLAGS_CONTROLLABLE)
            trim = _deg(g.trim_needed) if has(mav.ELLIPSLED_GUIDANCE_FLAGS_TRIM) else "none"
            t.add_row(Text("bank auth.", style="bold"),
                      Text(f"+{math.degrees(g.authority_pos):.2f} / -{math.degrees(g.authority_neg):.2f} °/s²",
                           style="green" if ok else "bold red"))
            t.add_row("bias / trim", f"{g.bias:.0f} N m / {trim.strip()}")
        return t

    def _jet_table(self) -> Table:
        js = self.client.state.latest.get("ELLIPSLED_JET_STATUS")
        t = Table(title="jets: cmd / fire / health", show_header=False, box=None, padding=(0, 1))
        cols = 6
        for _ in range(cols):
            t.add_column(justify="center")
        cells = []
        for j in range(N_JETS):
            if js is None:
                cells.append(Text(f"{j + 1:2d} ---", style="dim"))
                continue
            cmd = "●" if js.commanded >> j & 1 else "·"
            fire = "*" if js.firing >> j & 1 else "·"
            code = int(js.health[j])
            if code in JetState._value2member_map_:
                letter, style = JetState(code).name[0], HEALTH_STYLE[code]
            else:
                letter, style = "?", "white"
            cells.append(Text(f"{j + 1:2d} {cmd}{fire}{letter}", style=style))
        for r in range(0, N_JETS, cols):
            t.add_row(*cells[r:r + cols])
        return t

    def _timing_table(self) -> Table:
        t = Table.grid(padding=(0, 1))
        t.add_column(style="bold")
        t.add_column()
        lt = self.client.state.latest.get("ELLIPSLED_LOOP_TIMING")
        cs = self.client.state.latest.get("ELLIPSLED_CONTROL_STATUS")
        if lt is not None:
            t.add_row(f"RG{lt.rate_group} compute", f"p50 {lt.compute_p50:.0f} p99 {lt.compute_p99:.0f} "
                                                     f"max {lt.compute_max:.0f} us")
            t.add_row("jitter", f"p50 {lt.jitter_p50:.0f} p99 {lt.jitter_p99:.0f} max {lt.jitter_max:.0f} us")
            t.add_row("cycle slips", str(lt.cycle_slips))
        if cs is not None:
            t.add_row("allocator", f"{cs.alloc_solves} solves p99 {cs.alloc_p99:.0f} us, {cs.alloc_degraded} degraded")
            t.add_row("u_cal", " ".join(f"{x:7.0f}" for x in cs.u_cal) + " N m")
        if lt is None and cs is None:
            t.add_row("timing", "-")
        return t
