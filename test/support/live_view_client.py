"""The Foxglove WebSocket test client (test/foxglove_client/client.mjs), for tests and the bench.

:func:`ensure_installed` puts its npm packages in place (``npm ci``, once per machine; ``make
test`` and ``make bench`` do it first); :func:`start_client` runs it against a live_view.
"""

from __future__ import annotations

import base64
import json
import os
import shutil
import socket
import struct
import subprocess
from pathlib import Path

CLIENT_DIR = Path(__file__).resolve().parents[1] / "foxglove_client"


def ensure_installed() -> Path:
    """The client's directory, its npm packages installed; RuntimeError (with why) when they cannot be."""
    if shutil.which("node") is None or shutil.which("npm") is None:
        raise RuntimeError("node and npm are needed for the live_view client (Node 20 or newer)")
    if not (CLIENT_DIR / "node_modules" / "@foxglove" / "ws-protocol").is_dir():
        result = subprocess.run(
            ["npm", "ci", "--no-audit", "--no-fund"], cwd=CLIENT_DIR, capture_output=True, text=True, timeout=300
        )
        if result.returncode != 0:
            raise RuntimeError(f"npm ci in {CLIENT_DIR} failed: {result.stderr[-2000:]}")
    return CLIENT_DIR


def start_client(port: int, seconds: float, topics: str = "*") -> subprocess.Popen:
    """Run the client on ``ws://127.0.0.1:port`` for ``seconds`` after it connects, subscribed to
    ``topics`` (comma-separated, ``*`` = all); its stdout is one JSON object (see client.mjs)."""
    return subprocess.Popen(
        ["node", "client.mjs", f"ws://127.0.0.1:{port}", str(seconds), topics],
        cwd=ensure_installed(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _read_frame(sock: socket.socket) -> tuple[int, bytes]:
    def exactly(n: int) -> bytes:
        data = b""
        while len(data) < n:
            chunk = sock.recv(n - len(data))
            assert chunk, "server closed the connection"
            data += chunk
        return data

    first, second = exactly(2)
    length = second & 0x7F
    if length == 126:
        (length,) = struct.unpack(">H", exactly(2))
    elif length == 127:
        (length,) = struct.unpack(">Q", exactly(8))
    return first & 0x0F, exactly(length)


def _send_text(sock: socket.socket, text: str) -> None:
    payload, mask = text.encode(), os.urandom(4)
    header = b"\x81" + (
        bytes([0x80 | len(payload)]) if len(payload) < 126 else b"\xfe" + struct.pack(">H", len(payload))
    )
    sock.sendall(header + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload)))


def stalled_client(port: int) -> socket.socket:
    """A Foxglove WebSocket client of ``port`` that subscribes to every channel and never reads
    again (its receive buffer 4 kB): the client a live view must not be held back by."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.settimeout(10)
    sock.connect(("127.0.0.1", port))
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall(
        (
            f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
            f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n"
        ).encode()
    )
    response = b""
    while b"\r\n\r\n" not in response:
        response += sock.recv(1)
    assert b" 101 " in response.split(b"\r\n")[0], response
    while True:
        opcode, payload = _read_frame(sock)
        if opcode == 1 and json.loads(payload).get("op") == "advertise":
            channels = json.loads(payload)["channels"]
            break
    subscriptions = [{"id": i, "channelId": c["id"]} for i, c in enumerate(channels)]
    _send_text(sock, json.dumps({"op": "subscribe", "subscriptions": subscriptions}))
    return sock
