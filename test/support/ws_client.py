"""A minimal WebSocket client (RFC 6455, standard library only) speaking the Foxglove WebSocket protocol
(``foxglove.sdk.v1``, the name ``foxglove-sdk`` 0.30 servers accept; earlier servers spoke
``foxglove.websocket.v1``, offered second): enough to check what ``kite_foxglove`` serves without the Foxglove app.

It opens the connection with the subprotocol, reads the server's JSON text frames (``serverInfo``, ``advertise``,
...) and binary frames (opcode 0x01 = message data: subscription id u32, log time u64 ns, payload; little
endian), sends ``subscribe`` requests, answers pings and masks what it sends, as a client must.
"""
from __future__ import annotations

import base64
import json
import os
import socket
import struct
import time

SUBPROTOCOLS = ("foxglove.sdk.v1", "foxglove.websocket.v1")


class FoxgloveWsClient:
    def __init__(self, host: str, port: int, timeout: float = 30.0, subprotocols=SUBPROTOCOLS):
        self.sock = socket.create_connection((host, port), timeout=timeout)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall((f"GET / HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                           f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
                           f"Sec-WebSocket-Protocol: {', '.join(subprotocols)}\r\n\r\n").encode())
        head = b""
        while b"\r\n\r\n" not in head:
            chunk = self.sock.recv(1)
            if not chunk:
                raise ConnectionError(f"server closed during the handshake: {head!r}")
            head += chunk
        lines = head.decode(errors="replace").split("\r\n")
        if " 101 " not in lines[0] + " ":
            raise ConnectionError(f"handshake refused: {lines[0]}")
        self.headers = {ln.split(":", 1)[0].strip().lower(): ln.split(":", 1)[1].strip() for ln in lines[1:] if ":" in ln}
        self.subprotocol = self.headers.get("sec-websocket-protocol")
        self._buf = b""
        self.channels: dict = {}          # channel id -> advertised channel (dict)
        self.server_info: dict | None = None
        self.texts: list = []             # every JSON message received

    # ------------------------------------------------------------------------------------------ frames
    def _read(self, n: int) -> bytes:
        while len(self._buf) < n:
            chunk = self.sock.recv(65536)
            if not chunk:
                raise ConnectionError("server closed the connection")
            self._buf += chunk
        out, self._buf = self._buf[:n], self._buf[n:]
        return out

    def _frame(self):
        b0, b1 = self._read(2)
        fin, opcode, n = b0 & 0x80, b0 & 0x0F, b1 & 0x7F
        if n == 126:
            n = struct.unpack(">H", self._read(2))[0]
        elif n == 127:
            n = struct.unpack(">Q", self._read(8))[0]
        mask = self._read(4) if b1 & 0x80 else None
        data = self._read(n)
        if mask:
            data = bytes(c ^ mask[i % 4] for i, c in enumerate(data))
        return bool(fin), opcode, data

    def _send(self, opcode: int, data: bytes) -> None:
        mask = os.urandom(4)
        n = len(data)
        head = bytes([0x80 | opcode])
        if n < 126:
            head += bytes([0x80 | n])
        elif n < 1 << 16:
            head += bytes([0x80 | 126]) + struct.pack(">H", n)
        else:
            head += bytes([0x80 | 127]) + struct.pack(">Q", n)
        self.sock.sendall(head + mask + bytes(c ^ mask[i % 4] for i, c in enumerate(data)))

    def receive(self):
        """The next data message: ("json", dict) or ("binary", bytes); pings answered, fragments joined."""
        parts, first = [], None
        while True:
            fin, opcode, data = self._frame()
            if opcode == 0x9:
                self._send(0xA, data)
                continue
            if opcode == 0xA:
                continue
            if opcode == 0x8:
                raise ConnectionError("server sent close")
            if opcode != 0x0:
                first = opcode
            parts.append(data)
            if fin:
                break
        data = b"".join(parts)
        if first == 0x1:
            msg = json.loads(data.decode())
            self.texts.append(msg)
            if msg.get("op") == "serverInfo":
                self.server_info = msg
            elif msg.get("op") == "advertise":
                for ch in msg["channels"]:
                    self.channels[ch["id"]] = ch
            elif msg.get("op") == "unadvertise":
                for cid in msg["channelIds"]:
                    self.channels.pop(cid, None)
            return "json", msg
        return "binary", data

    # ------------------------------------------------------------------------------------------ protocol
    def send_json(self, msg: dict) -> None:
        self._send(0x1, json.dumps(msg).encode())

    def subscribe(self, channel_ids: dict) -> None:
        """``channel_ids``: subscription id -> channel id."""
        self.send_json({"op": "subscribe", "subscriptions": [{"id": s, "channelId": c} for s, c in channel_ids.items()]})

    def wait_for_channels(self, topics, timeout: float) -> dict:
        """Read until every topic in ``topics`` is advertised; return topic -> channel."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            have = {ch["topic"]: ch for ch in self.channels.values()}
            if all(t in have for t in topics):
                return have
            self.receive()
        raise TimeoutError(f"not advertised within {timeout} s: {sorted(set(topics) - set(have))}")

    @staticmethod
    def message_data(data: bytes):
        """(subscription id, log time ns, payload) of a binary message-data frame, or None for another opcode."""
        if not data or data[0] != 0x01:
            return None
        sub, log_time = struct.unpack_from("<IQ", data, 1)
        return sub, log_time, data[13:]

    def close(self) -> None:
        try:
            self._send(0x8, struct.pack(">H", 1000))
        except OSError:
            pass
        self.sock.close()
