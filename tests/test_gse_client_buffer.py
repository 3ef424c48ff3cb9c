"""The ground end keeps what arrives while it is starved of CPU, and counts what it could
not keep (gse/client.py RX_BUFFER_BYTES, stats["rx_kernel_drops"] from the kernel's own
counter of the socket). Real sockets on loopback."""
from __future__ import annotations

import socket
import sys

import pytest

from gse.client import GroundClient
from interfaces.mavlink.intake import kernel_drops

N = 1500                      # ~15 s of the default streams; the system default buffer holds ~150
SYSTEM_DEFAULT_RCVBUF = 212992


def _burst(addr, n: int) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
        for i in range(n):
            tx.sendto(b"\xfd" + i.to_bytes(4, "little") + bytes(35), addr)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="SO_MEMINFO drop counter is Linux's")
def test_a_starved_console_keeps_a_burst_and_counts_what_a_small_buffer_drops():
    c = GroundClient(None, listen="udp:127.0.0.1:0")
    try:
        if c.rx_buffer_bytes < 4 << 20:        # unprivileged, net.core.rmem_max below 4 MiB
            pytest.skip(f"receive buffer granted {c.rx_buffer_bytes} B (net.core.rmem_max caps it; "
                        "no CAP_NET_ADMIN): too small to hold the burst")
        assert kernel_drops(c.sock) == 0
        _burst(c.address, N)                       # nothing read meanwhile: the console starved
        c.poll()
        assert c.stats["rx_datagrams"] == N
        assert c.stats["rx_kernel_drops"] == 0
        # the same burst into the system's default buffer: most of it is lost, and counted
        c.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, SYSTEM_DEFAULT_RCVBUF // 2)
        _burst(c.address, N)
        c.poll()
        got = c.stats["rx_datagrams"] - N
        assert c.stats["rx_kernel_drops"] > 0
        assert got + c.stats["rx_kernel_drops"] == N
    finally:
        c.close()
