"""Test session setup: DDS on loopback with a random free domain id.

This runs before any test module imports rclpy, so every node started in
pytest, and every subprocess a test starts, inherits the same isolated domain.
"""

import os
import random
import socket
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]


def _domain_is_free(domain_id: int) -> bool:
    # Fast DDS binds the first participant's unicast discovery port to
    # 7410 + 250 * domain; if that is taken another participant uses the domain.
    port = 7410 + 250 * domain_id
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def _pick_free_domain() -> int:
    candidates = list(range(1, 101))
    random.SystemRandom().shuffle(candidates)
    for domain_id in candidates:
        if _domain_is_free(domain_id):
            return domain_id
    raise RuntimeError("no free ROS_DOMAIN_ID in 1..100")


os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ["ROS_DOMAIN_ID"] = str(_pick_free_domain())
os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
os.environ.setdefault("PYTHONUNBUFFERED", "1")
os.environ.setdefault("MPLBACKEND", "Agg")
