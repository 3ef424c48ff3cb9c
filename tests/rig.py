"""The ground-link rig the ground-link and gse tests share: a FlightSoftware built from a
scenario (case1 by default) with its scheduled faults removed (the tests inject from the
ground), the plant from sim.plant, a GroundLink on an ephemeral port with a fake scheduling
clock, and a GroundClient with a key file written in tmp_path; stepped by the test. Beside
it, ``Keyless``: a ground station without the key on a port of its own (fixture ``station``),
and ``PricedReads``: a socket whose reads cost time on an injected clock.
"""
from __future__ import annotations

import socket
import time
from contextlib import contextmanager

import pytest

from common.model import load_scenario
from fsw.executive import divisors
from fsw.flightsoftware import FlightSoftware
from fsw.groundlink import GroundLink
from gse.client import GroundClient
from gse.commands import make_request
from interfaces.mavlink import dialect as mav
from interfaces.mavlink.signing.keys import SigningKey
from sim.plant import Plant

ACCEPTED, DENIED, UNSUPPORTED = mav.MAV_RESULT_ACCEPTED, mav.MAV_RESULT_DENIED, mav.MAV_RESULT_UNSUPPORTED


class Clock:
    def __init__(self, t: float = 1000.0):
        self.t = t

    def __call__(self) -> float:
        return self.t


class NsClock:
    """A ns clock that moves only when a test (or what it prices) moves it."""

    def __init__(self) -> None:
        self.t = 0

    def __call__(self) -> int:
        return self.t


class PricedReads:
    """A socket whose each read costs ``read_ns`` on ``clock`` (anything with a ns ``t``):
    an injected clock's price for the intake's socket read."""

    def __init__(self, sock, clock, read_ns: int):
        self.sock, self.clock, self.read_ns = sock, clock, read_ns

    def recvfrom_into(self, *args):
        self.clock.t += self.read_ns
        return self.sock.recvfrom_into(*args)

    def __getattr__(self, name):
        return getattr(self.sock, name)


def write_key(tmp_path, name: str = "ground.key") -> SigningKey:
    path = tmp_path / name
    SigningKey.generate().write_file(path)
    return SigningKey.from_file(path)


class Rig:
    """FSW + plant + ground link + ground client, stepped by the test."""

    def __init__(self, tmp_path, *, inject="plant", rates=None, tlog=None, key=None, scenario="case1"):
        # case1 with its scheduled faults removed: the ground injects them instead
        self.scn = load_scenario(scenario).with_(faults=())
        self.plant = Plant(self.scn)
        self.fsw = FlightSoftware(self.scn)
        self.key = key or write_key(tmp_path)
        self.clock = Clock()
        self.injected: list[tuple[int, str, float]] = []
        self.inject_answer = True
        self.gcs = GroundClient(self.key, listen="udp:127.0.0.1:0", tlog=tlog)
        cb = self._inject if inject == "plant" else inject
        # the tick's budget on a clock that stands still: what a tick sends is the logic's,
        # not the host's (tests/test_groundlink_budget.py prices the frames instead)
        self.gl = GroundLink(self.fsw, self.key, gcs=f"udp:127.0.0.1:{self.gcs.address[1]}",
                             bind="udp:127.0.0.1:0", inject=cb, rates=rates, clock=self.clock,
                             tick_clock_ns=lambda: 0)
        self.gcs.set_vehicle(self.gl.address)
        self.frame = self.plant.sensors
        self.k = 0

    def _inject(self, jet, kind, eta):
        self.injected.append((jet, kind, eta))
        if self.inject_answer is not True:
            return self.inject_answer
        self.plant.set_fault(jet, kind, eta)
        return True

    def fly(self, n: int, tick_every: int = 5, listen: bool = True) -> None:
        """n control cycles; the link ticks every ``tick_every`` (RG2) and listens on the
        cycles between (as the SIL's FSW does; ``listen=False``: it does not), the fake
        clock advancing by the time that elapsed in simulation."""
        rg3 = divisors(self.fsw.params, self.fsw.dt_s)[2]
        for _ in range(n):
            u = self.fsw.control_step(self.frame)
            if self.k % rg3 == 0:
                self.fsw.entry_guidance_step()        # mode npc only (a no-op in profile)
            if self.k % tick_every == 0:
                self.clock.t += tick_every * self.scn.dt_control_s
                self.gl.tick(self.frame)
                self.gcs.poll(0.0)
            elif listen:
                self.gl.listen()
            self.frame = self.plant.step(u)
            self.k += 1

    def exchange(self, until, timeout_s: float = 3.0) -> bool:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            self.gl.tick(self.frame)
            self.gcs.poll(0.005)
            if until():
                return True
        return False

    def command(self, *words):
        pc = self.gcs.start(make_request(*words), timeout_s=1.0, retries=2)
        assert self.exchange(lambda: pc.done), f"no ACK for {words}"
        return pc.result

    def raw_command(self, command: int, *params):
        pc = self.gcs.start_command(command, *params, timeout_s=1.0, retries=2)
        assert self.exchange(lambda: pc.done), f"no ACK for command {command}"
        return pc.result

    def texts(self) -> list[str]:
        self.exchange(lambda: False, 0.05)
        return [e.text for e in self.gcs.state.events]

    def close(self):
        self.gl.close()
        self.gcs.close()
        self.fsw.close()


@contextmanager
def flown(tmp_path, cycles: int = 10, **rig_options):
    """A Rig (``rig_options`` as Rig's) flown ``cycles`` control cycles; closed afterwards."""
    r = Rig(tmp_path, **rig_options)
    try:
        r.fly(cycles)
        yield r
    finally:
        r.close()


@pytest.fixture
def rig(tmp_path):
    with flown(tmp_path) as r:
        yield r


class Keyless:
    """A ground station without the key on its own UDP port: packs unsigned, parses all."""

    def __init__(self, rig):
        self.rig = rig
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.mav = mav.MAVLink(None, srcSystem=245, srcComponent=190)
        self.parser = mav.MAVLink(None)
        self.got: list = []

    @property
    def address(self):
        return self.sock.getsockname()

    def send(self, msg) -> None:
        self.sock.sendto(msg.pack(self.mav), self.rig.gl.address)

    def command(self, command: int, *p: float) -> None:
        p = list(p) + [0.0] * (7 - len(p))
        self.send(mav.MAVLink_command_long_message(1, 1, command, 0, *p))

    def _drain(self) -> None:
        while True:
            try:
                data = self.sock.recv(4096)
            except BlockingIOError:
                return
            for m in self.parser.parse_buffer(data) or []:
                self.got.append(m)

    def wait(self, cond, timeout_s: float = 2.0) -> bool:
        def done():
            self._drain()
            return cond()
        return self.rig.exchange(done, timeout_s)

    def of(self, name: str) -> list:
        self._drain()
        return [m for m in self.got if m.get_type() == name]

    def close(self) -> None:
        self.sock.close()


@pytest.fixture
def station(rig):
    k = Keyless(rig)
    yield k
    k.close()
