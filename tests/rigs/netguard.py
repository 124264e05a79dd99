"""A packet capture on every interface (AF_PACKET, needs root) that tests run around a GigE
Vision camera on loopback, to show Aravis sent nothing but unicast to 127.0.0.1."""

from __future__ import annotations

import socket
import struct
import threading

GVCP_PORT = 3956


class PacketGuard:
    """Records ``(interface, src, dst, sport, dport)`` of every IPv4 UDP packet until :meth:`close`."""

    def __init__(self):
        self._sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(0x0003))
        self._sock.settimeout(0.05)
        self.packets: list[tuple[str, str, str, int, int]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="packet-guard", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                data, addr = self._sock.recvfrom(65535)
            except TimeoutError:
                continue
            if len(data) < 42 or struct.unpack("!H", data[12:14])[0] != 0x0800 or data[23] != 17:
                continue
            ihl = (data[14] & 15) * 4
            sport, dport = struct.unpack("!HH", data[14 + ihl : 18 + ihl])
            self.packets.append((addr[0], socket.inet_ntoa(data[26:30]), socket.inet_ntoa(data[30:34]), sport, dport))

    def close(self) -> list[tuple[str, str, str, int, int]]:
        self._stop.set()
        self._thread.join()
        self._sock.close()
        return self.packets

    def offending(self) -> list[tuple]:
        """GigE Vision traffic (port 3956) or broadcasts anywhere but loopback between 127.0.0.1."""
        return [p for p in self.packets
                if (GVCP_PORT in (p[3], p[4]) or p[2].endswith(".255"))
                and not (p[0] == "lo" and p[1] == p[2] == "127.0.0.1")]  # fmt: skip
