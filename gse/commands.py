"""The operator's command language, shared by the console's command line and the scripted
``ellipsled gse`` commands: words ("inject 17 failed_off", "param set C_D_MIN 0.4") -> a Request
(a COMMAND_LONG or a parameter action) that gse/client.py sends. The kind and mode words
are the vocabulary's (interfaces/vocabulary.py); any unambiguous prefix is accepted
("mark 7 failed" = failed_off). Bad words raise ValueError naming the word (and, for a
retired jet-state word such as "off", the word that replaced it).
"""
from __future__ import annotations

from dataclasses import dataclass

from interfaces.mavlink import dialect as mav
from interfaces.vocabulary import FAULT_KINDS, MARK_KINDS, N_JETS, Mode, renamed

MODES = {m.name.lower(): int(m) for m in Mode}
ON_OFF = {"on": 1, "off": 0}

USAGE = f"""commands:
  inject JET {'|'.join(k for k in FAULT_KINDS if k != 'degraded')}    (JET 1..{N_JETS}, 0 = all)
  inject JET degraded ETA
  clear JET                          (FDIR latch, override, inhibit; 0 = all)
  mark JET {'|'.join(k for k in MARK_KINDS if k != 'degraded')}
  mark JET degraded ETA
  mode {'|'.join(MODES)}            arm on|off            ft on|off
  delay SECONDS                      (FDIR reconfiguration delay)
  param list | param get ID | param set ID VALUE"""


@dataclass(frozen=True)
class Request:
    """One operator request: a COMMAND_LONG (``command``, ``params``) or a parameter
    action (``param``: 'list' | 'get' | 'set')."""
    label: str
    command: int = 0
    params: tuple[float, ...] = ()
    param: str = ""
    param_id: str = ""
    value: float = float("nan")


def _num(word: str, what: str) -> float:
    try:
        v = float(word)
    except ValueError:
        raise ValueError(f"{what}: expected a number, got {word!r}") from None
    return v


def _jet(word, allow_all: bool) -> int:
    try:
        j = int(word)
    except (TypeError, ValueError):
        raise ValueError(f"jet: expected an integer, got {word!r}") from None
    lo = 0 if allow_all else 1
    if not lo <= j <= N_JETS:       # also checked by the vehicle; caught early for the operator
        raise ValueError(f"jet: must be in {lo}..{N_JETS}{' (0 = all)' if allow_all else ''}, got {j}")
    return j


def _choice(word: str, table: dict, what: str):
    """(name, value) of the entry ``word`` names exactly or is the only prefix of."""
    w = str(word).lower()
    hits = [w] if w in table else [k for k in table if k.startswith(w)] if w else []
    if len(hits) != 1:
        raise ValueError(f"{what}: expected one of {'|'.join(table)}, got {word!r}{renamed(w, table)}")
    return hits[0], table[hits[0]]


def make_request(verb: str, *args: str) -> Request:
    """A Request from words, e.g. ("inject", "17", "failed_off"), ("param", "set", "C_D_MIN", "0.4").
    ValueError with a message naming the bad word."""
    verb = verb.lower()
    a = list(args)

    def need(n_min: int, n_max: int, usage: str):
        if not n_min <= len(a) <= n_max:
            raise ValueError(f"usage: {usage}")

    def jet_kind_eta(table: dict, allow_all: bool, eta_default: float):
        """JET KIND [ETA]: ETA only (and always) for degraded."""
        need(2, 3, f"{verb} JET {'|'.join(table)} [ETA]")
        jet = _jet(a[0], allow_all)
        kind, code = _choice(a[1], table, "kind")
        eta = eta_default
        if kind == "degraded":
            if len(a) != 3:
                raise ValueError(f"{verb} degraded needs ETA in (0, 1)")
            eta = _num(a[2], "eta")
        elif len(a) == 3:
            raise ValueError(f"eta applies to degraded only (kind {kind})")
        return jet, kind, code, eta, f"{verb} jet {jet} {kind}" + (f" eta {eta:g}" if kind == "degraded" else "")

    if verb == "inject":
        jet, kind, ftype, eta, label = jet_kind_eta(FAULT_KINDS, True, 0.0)
        return Request(label, mav.MAV_CMD_INJECT_FAILURE, (mav.FAILURE_UNIT_SYSTEM_MOTOR, ftype, jet, eta))
    if verb == "mark":
        jet, kind, code, eta, label = jet_kind_eta(MARK_KINDS, False, 1.0)
        return Request(label, mav.ELLIPSLED_CMD_FDIR_MARK_JET, (jet, code, eta))
    if verb == "clear":
        need(1, 1, "clear JET (0 = all)")
        jet = _jet(a[0], True)
        return Request(f"clear jet {jet}", mav.ELLIPSLED_CMD_FDIR_CLEAR, (jet,))
    if verb == "mode":
        need(1, 1, f"mode {'|'.join(MODES)}")
        name, code = _choice(a[0], MODES, "mode")
        return Request(f"mode {name}", mav.ELLIPSLED_CMD_SET_MODE, (code,))
    if verb == "arm":
        need(1, 1, "arm on|off")
        name, v = _choice(a[0], ON_OFF, "arm")
        return Request(f"arm {name}", mav.ELLIPSLED_CMD_ARM_JETS, (v,))
    if verb == "ft":
        need(1, 1, "ft on|off")
        name, v = _choice(a[0], ON_OFF, "ft")
        return Request(f"fault tolerance {name}", mav.ELLIPSLED_CMD_FAULT_TOLERANCE, (v,))
    if verb == "delay":
        need(1, 1, "delay SECONDS")
        d = _num(a[0], "delay")
        return Request(f"fdir delay {d:g} s", mav.ELLIPSLED_CMD_FDIR_SET_DELAY, (d,))
    if verb == "param":
        if not a:
            raise ValueError("usage: param list | param get ID | param set ID VALUE")
        sub = a[0].lower()
        if sub == "list" and len(a) == 1:
            return Request("param list", param="list")
        if sub == "get" and len(a) == 2:
            return Request(f"param get {a[1].upper()}", param="get", param_id=a[1].upper())
        if sub == "set" and len(a) == 3:
            return Request(f"param set {a[1].upper()} {a[2]}", param="set", param_id=a[1].upper(),
                           value=_num(a[2], "value"))
        raise ValueError("usage: param list | param get ID | param set ID VALUE")
    raise ValueError(f"unknown command {verb!r}\n{USAGE}")


def parse_line(text: str) -> Request:
    """A Request from one command line ("inject 17 failed_off")."""
    words = str(text).split()
    if not words:
        raise ValueError(USAGE)
    return make_request(words[0], *words[1:])


__all__ = ["Request", "make_request", "parse_line", "USAGE", "MODES"]
