"""Two hosts on one machine: two network namespaces joined by a veth pair (for the across-hosts
test and bench/bench_across_hosts.py).

:class:`HostPair` creates ``<tag>a`` and ``<tag>b`` (a tag unique to this process and call),
a veth pair with one end in each (10.231.0.1/24 in a, 10.231.0.2/24 in b), ``lo`` up in both,
and removes all of it on exit, also after a failure (deleting a namespace deletes its veth
end, and with it the pair). Nothing is added outside the two namespaces: no address, route or
link of the machine's own network changes.

DDS across the pair (:func:`host_env`, the same environment on both sides):
``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET`` and ``ROS_STATIC_PEERS`` = both namespaces'
addresses, on UDP only. Why each:

* LOCALHOST (the tests' setting) sends discovery to 127.0.0.1 only; a namespace's loopback is
  its own, so nothing would cross. SUBNET is safe here: the namespace's only interfaces are
  its ``lo`` and its veth end, whose subnet has one other host, the other namespace.
* A namespace has no route to multicast (no default route): each gets one over its veth end
  (224.0.0.0/4), without which discovery across took about 40 s in four runs in a row. The
  static peers make Fast DDS send its unicast discovery to the other side's address as well (rmw_fastrtps adds them to the initial peers; a process's own
  address among them costs it a few discovery packets to itself, and keeps one environment
  for both sides, so a process started across with ``ip netns exec`` inherits the right one).
* ``FASTDDS_BUILTIN_TRANSPORTS=UDPv4``: namespaces share /dev/shm, so Fast DDS's shared-memory
  transport would carry the data past the veth and a link down would cut nothing. (With
  SUBNET rmw_fastrtps keeps Fast DDS's built-in transports, so the variable takes effect.)
"""

from __future__ import annotations

import itertools
import os
import shutil
import subprocess
from collections.abc import Mapping, Sequence

SUBNET_PREFIX = "10.231.0"
_pairs = itertools.count()


def unavailable_reason() -> str:
    """Why network namespaces cannot be made here ("" when they can)."""
    if shutil.which("ip") is None:
        return "no `ip` command (iproute2) on this machine"
    if os.geteuid() != 0:
        return "network namespaces need root (ip netns add)"
    probe = f"mkprobe{os.getpid() % 100000}"
    made = subprocess.run(["ip", "netns", "add", probe], capture_output=True, text=True)
    if made.returncode != 0:
        return f"ip netns add failed: {made.stderr.strip()}"
    subprocess.run(["ip", "netns", "delete", probe], capture_output=True)
    return ""


def _ip(*args: str) -> None:
    result = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=10)
    if result.returncode != 0:
        raise RuntimeError(f"ip {' '.join(args)}: {result.stderr.strip()}")


class HostPair:
    """Two network namespaces ``a`` and ``b`` joined by a veth pair; a context manager.

    ``HostPair(tag)`` names the pair another process made (its :attr:`tag`), to run commands
    in it or take its link down, without entering it (only the maker removes it).

    Attributes:
        names: ``{"a": namespace, "b": namespace}``.
        addresses: ``{"a": "10.231.0.1", "b": "10.231.0.2"}``.
        links: the veth end in each namespace, ``{"a": ..., "b": ...}``.
    """

    def __init__(self, tag: str = ""):
        # Interface names have at most 15 characters: mk + pid (≤ 7 digits) + call + side.
        #: What the names derive from: pass it to another process to reach the same pair.
        self.tag = tag or f"mk{os.getpid()}{next(_pairs)}"
        tag = self.tag
        self.names = {"a": f"{tag}a", "b": f"{tag}b"}
        self.links = {"a": f"{tag}x", "b": f"{tag}y"}
        self.addresses = {"a": f"{SUBNET_PREFIX}.1", "b": f"{SUBNET_PREFIX}.2"}

    def __enter__(self) -> HostPair:
        try:
            for side in "ab":
                _ip("netns", "add", self.names[side])
            _ip(
                "link", "add", self.links["a"], "netns", self.names["a"], "type", "veth",
                "peer", "name", self.links["b"], "netns", self.names["b"],
            )  # fmt: skip
            for side in "ab":
                self.run(side, "ip", "link", "set", "lo", "up")
                self.run(side, "ip", "addr", "add", f"{self.addresses[side]}/24", "dev", self.links[side])
                self.run(side, "ip", "link", "set", self.links[side], "up")
                # Multicast over the veth: Fast DDS's participant announcements reach the other side
                # without depending on the static peers' port guesses alone.
                self.run(side, "ip", "route", "add", "224.0.0.0/4", "dev", self.links[side])
        except BaseException:
            self.remove()
            raise
        return self

    def __exit__(self, *exc) -> None:
        self.remove()

    def remove(self) -> None:
        """Delete both namespaces (and so the veth pair); quiet about what is already gone."""
        for name in self.names.values():
            subprocess.run(["ip", "netns", "delete", name], capture_output=True, timeout=10)

    def prefix(self, side: str) -> tuple[str, ...]:
        """The command prefix that runs a program in namespace ``side``."""
        return ("ip", "netns", "exec", self.names[side])

    def run(self, side: str, *command: str) -> None:
        """Run a short command (``ip ...``) in namespace ``side``; RuntimeError when it fails."""
        _ip("netns", "exec", self.names[side], *command)

    def set_link(self, up: bool) -> None:
        """Take the veth link down (both ends, as a pulled cable) or bring it up again."""
        for side in "ab":
            self.run(side, "ip", "link", "set", self.links[side], "up" if up else "down")


def host_env(pair: HostPair, base: Mapping[str, str], domain_id: int | str) -> dict:
    """The DDS environment of a process in either namespace (see the module docstring)."""
    env = dict(base)
    env.update(
        ROS_AUTOMATIC_DISCOVERY_RANGE="SUBNET",
        ROS_STATIC_PEERS=";".join(pair.addresses.values()),
        ROS_DOMAIN_ID=str(domain_id),
        FASTDDS_BUILTIN_TRANSPORTS="UDPv4",
    )
    return env


def run_in(pair: HostPair, side: str, command: Sequence[str], env: Mapping[str, str], **kwargs):
    """``subprocess.run`` of ``command`` in namespace ``side``."""
    return subprocess.run([*pair.prefix(side), *command], env=dict(env), **kwargs)
