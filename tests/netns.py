"""Hosts for tests: Linux network namespaces on a private bridge, made and removed here.

``Network(["router", "plant", "fsw"])`` creates one namespace per host, each with its
loopback up and one interface ``eth0`` addressed ``10.231.<net>.<n>/24``, joined by a
bridge that lives in a namespace of its own (nothing is added to the machine's own
network stack; no route leads out: traffic stays between these hosts). Processes are
started inside a host with ``start`` (``ip netns exec`` replaces itself with the
command, so the pid is the process's own) and stopped by that pid with timeouts.
``close`` stops every process and deletes every namespace; it is safe after a failure
half way and is called by the fixtures' finalizers. Namespaces left by a test process
that was killed outright are swept by the next ``Network`` (their names carry the pid).

``skip_reason()`` says why hosts cannot be made here (no ``ip`` command, not permitted).
"""
from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import time
from pathlib import Path

from ellipsled.procs import stop_process

PREFIX = "elsn"             # namespace names: elsn<pid>x<net>-<host>
_NAME = re.compile(rf"^{PREFIX}(\d+)x")


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, timeout=20, check=check)


def skip_reason() -> str | None:
    """None when namespaces can be made here, else why not (for pytest.skip)."""
    if shutil.which("ip") is None:
        return "no `ip` command (iproute2) on this machine"
    probe = f"{PREFIX}{os.getpid()}xprobe"
    r = _ip("netns", "add", probe, check=False)
    if r.returncode != 0:
        return f"cannot create a network namespace (needs root or CAP_SYS_ADMIN + CAP_NET_ADMIN): {r.stderr.strip()}"
    try:
        r = _ip("-n", probe, "link", "add", "p0", "type", "veth", "peer", "name", "p1", check=False)
        if r.returncode != 0:
            return f"cannot create a veth pair in a namespace: {r.stderr.strip()}"
        r = _ip("-n", probe, "link", "add", "b0", "type", "bridge", check=False)
        if r.returncode != 0:
            return f"cannot create a bridge in a namespace: {r.stderr.strip()}"
    finally:
        _ip("netns", "delete", probe, check=False)
    return None


def sweep_stale() -> None:
    """Delete namespaces of this naming whose test process is gone."""
    r = _ip("netns", "list", check=False)
    for line in r.stdout.splitlines():
        name = line.split()[0] if line.strip() else ""
        m = _NAME.match(name)
        if m and not Path(f"/proc/{m.group(1)}").exists():
            _ip("netns", "delete", name, check=False)


class Network:
    _count = 0

    def __init__(self, hosts: list[str], log_dir: Path):
        Network._count += 1
        self.net = Network._count % 250 + 1
        self.tag = f"{PREFIX}{os.getpid()}x{self.net}"
        self.log_dir = Path(log_dir)
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.switch = f"{self.tag}-sw"
        self.hosts: dict[str, tuple[str, str]] = {}          # host -> (namespace, address)
        self.procs: dict[str, tuple[str, subprocess.Popen]] = {}   # name -> (host, process)
        self._port: dict[str, int] = {}                         # host -> its port number on the bridge
        self._logs = []
        sweep_stale()
        try:
            _ip("netns", "add", self.switch)
            _ip("-n", self.switch, "link", "add", "br0", "type", "bridge")
            _ip("-n", self.switch, "link", "set", "br0", "up")
            for i, h in enumerate(hosts, start=1):
                self.add_host(h, i)
        except BaseException:
            self.close()
            raise

    def add_host(self, host: str, n: int) -> None:
        ns, addr = f"{self.tag}-{host}", f"10.231.{self.net}.{n}"
        _ip("netns", "add", ns)
        self.hosts[host] = (ns, addr)
        self._port[host] = n
        _ip("-n", ns, "link", "set", "lo", "up")
        _ip("-n", self.switch, "link", "add", f"v{n}", "type", "veth", "peer", "name", "eth0", "netns", ns)
        _ip("-n", self.switch, "link", "set", f"v{n}", "master", "br0")
        _ip("-n", self.switch, "link", "set", f"v{n}", "up")
        _ip("-n", ns, "addr", "add", f"{addr}/24", "dev", "eth0")
        _ip("-n", ns, "link", "set", "eth0", "up")

    def addr(self, host: str) -> str:
        return self.hosts[host][1]

    def start(self, name: str, host: str, argv: list[str], *, cwd: Path | None = None,
              env: dict | None = None) -> subprocess.Popen:
        """Start ``argv`` on ``host``; output to ``<log_dir>/<name>.log``."""
        log = open(self.log_dir / f"{name}.log", "w")
        self._logs.append(log)
        p = subprocess.Popen(["ip", "netns", "exec", self.hosts[host][0], *argv], cwd=cwd, env=env,
                             stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        self.procs[name] = (host, p)
        return p

    def log(self, name: str) -> str:
        return (self.log_dir / f"{name}.log").read_text()

    def wait_log(self, name: str, text: str, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        p = self.procs[name][1]
        while text not in self.log(name):
            if p.poll() is not None or time.monotonic() > deadline:
                raise AssertionError(f"{name}: no {text!r} (exit {p.poll()}) within {timeout_s} s:\n"
                                     f"{self.log(name)[-3000:]}")
            time.sleep(0.05)

    def wait(self, name: str, timeout_s: float) -> int:
        try:
            return self.procs[name][1].wait(timeout_s)
        except subprocess.TimeoutExpired:
            raise AssertionError(f"{name} did not finish within {timeout_s} s:\n{self.log(name)[-3000:]}") from None

    def stop(self, name: str, sig: int = signal.SIGTERM, timeout_s: float = 10.0) -> int:
        """Signal the process by its pid, wait; SIGKILL after ``timeout_s``."""
        return stop_process(self.procs[name][1], timeout_s, sig=sig)

    def unplug(self, host: str) -> None:
        """Cut the host's cable (its veth pair): nothing more reaches it or leaves it."""
        _ip("-n", self.switch, "link", "delete", f"v{self._port[host]}", check=False)

    def kill_all(self, host: str) -> None:
        """SIGKILL every process inside the host's namespace (also those our processes
        started, e.g. a Dask nanny's worker), and reap the ones started here."""
        ns = self.hosts[host][0]
        for _ in range(3):
            pids = [int(x) for x in _ip("netns", "pids", ns, check=False).stdout.split()]
            if not pids:
                break
            for pid in pids:
                try:
                    os.kill(pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
            time.sleep(0.1)
        for name, (h, p) in self.procs.items():
            if h == host and p.poll() is None:
                try:
                    p.wait(5)
                except subprocess.TimeoutExpired:
                    pass

    def remove_host(self, host: str) -> None:
        """The host is gone: cable cut, every process on it killed, its namespace deleted."""
        self.unplug(host)
        self.kill_all(host)
        ns = self.hosts.pop(host)[0]
        _ip("netns", "delete", ns, check=False)

    def close(self) -> None:
        for name in list(self.procs):
            try:
                self.stop(name, signal.SIGTERM, 5.0)
            except Exception:
                pass
        for host in list(self.hosts):
            self.kill_all(host)                     # whatever our processes left behind
        for log in self._logs:
            log.close()
        for ns, _ in list(self.hosts.values()):
            _ip("netns", "delete", ns, check=False)
        self.hosts.clear()
        _ip("netns", "delete", self.switch, check=False)

    def leftovers(self) -> list[str]:
        """Namespaces of this network still present (for the tests' own check)."""
        r = _ip("netns", "list", check=False)
        return [ln.split()[0] for ln in r.stdout.splitlines() if ln.startswith(self.tag)]
