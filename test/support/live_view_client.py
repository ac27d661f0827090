"""The Foxglove WebSocket test client (test/foxglove_client/client.mjs), for tests and the bench.

:func:`ensure_installed` puts its npm packages in place (``npm ci``, once per machine; ``make
test`` and ``make bench`` do it first); :func:`start_client` runs it against a live_view.
"""

from __future__ import annotations

import shutil
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
