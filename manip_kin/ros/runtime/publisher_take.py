"""A subscription whose messages come with the node that published them.

rclpy's take gives a message's timestamps and sequence numbers but not the publisher's GID,
which rcl has (``rmw_message_info_t.publisher_gid``). :class:`AttributedSubscription` takes
serialized messages with ``rcl_take_serialized_message`` through ctypes (the subscription's
rcl handle is ``Subscription.handle.pointer``, an rclpy internal like those of
:mod:`manip_kin.ros.runtime.polling`) and names each sender by matching its GID with the graph's
``get_publishers_info_by_topic``. It is used for rare messages only (``robot_description``),
from the executor thread or before the node spins.

Where that is not available (an rclpy release not checked, rcl not found) it falls back to a
public subscription whose messages have no sender (``None``); :attr:`attributed` says which.
"""

from __future__ import annotations

import collections
import ctypes
import os
import sys

from rclpy.node import Node
from rclpy.qos import QoSProfile

from manip_kin.ros.runtime.polling import CHECKED_RCLPY, _NeverExecutedGroup, _rclpy_version


class _Allocator(ctypes.Structure):
    _fields_ = [
        ("allocate", ctypes.c_void_p),
        ("deallocate", ctypes.c_void_p),
        ("reallocate", ctypes.c_void_p),
        ("zero_allocate", ctypes.c_void_p),
        ("state", ctypes.c_void_p),
    ]


class _ByteArray(ctypes.Structure):  # rcutils_uint8_array_t = rcl_serialized_message_t
    _fields_ = [
        ("buffer", ctypes.POINTER(ctypes.c_uint8)),
        ("buffer_length", ctypes.c_size_t),
        ("buffer_capacity", ctypes.c_size_t),
        ("allocator", _Allocator),
    ]


#: RMW_GID_STORAGE_SIZE of ROS 2 Jazzy.
GID_SIZE = 16


class _MessageInfo(ctypes.Structure):  # rmw_message_info_t
    _fields_ = [
        ("source_timestamp", ctypes.c_int64),
        ("received_timestamp", ctypes.c_int64),
        ("publication_sequence_number", ctypes.c_uint64),
        ("reception_sequence_number", ctypes.c_uint64),
        ("gid_implementation", ctypes.c_char_p),
        ("gid", ctypes.c_uint8 * GID_SIZE),
        ("from_intra_process", ctypes.c_bool),
        # Room for a larger layout of another release: rcl never writes past our struct.
        ("_reserved", ctypes.c_uint8 * 64),
    ]


def _load_rcl():
    """``(rcl, rcutils)`` with the three functions typed, or a string saying why not."""
    version = _rclpy_version()
    if not version.startswith(CHECKED_RCLPY):
        return f"rclpy {version or '(unknown version)'} is not one of the checked releases {CHECKED_RCLPY}"
    try:
        lib = os.path.join(sys.prefix, "lib")
        names = [(os.path.join(lib, f"lib{name}.so"), f"lib{name}.so") for name in ("rcl", "rcutils")]
        rcl, rcutils = (ctypes.CDLL(path if os.path.exists(path) else bare) for path, bare in names)
        rcutils.rcutils_get_default_allocator.restype = _Allocator
        rcutils.rcutils_uint8_array_init.argtypes = [
            ctypes.POINTER(_ByteArray),
            ctypes.c_size_t,
            ctypes.POINTER(_Allocator),
        ]
        rcutils.rcutils_uint8_array_fini.argtypes = [ctypes.POINTER(_ByteArray)]
        take = rcl.rcl_take_serialized_message
        take.argtypes = [ctypes.c_void_p, ctypes.POINTER(_ByteArray), ctypes.POINTER(_MessageInfo), ctypes.c_void_p]
        take.restype = ctypes.c_int
    except (OSError, AttributeError) as error:
        return f"rcl not found: {error}"
    return rcl, rcutils


_RCL = None


def _rcl():
    global _RCL
    if _RCL is None:
        _RCL = _load_rcl()
    return _RCL


class AttributedSubscription:
    """Serialized messages of one topic, each with the GID of its publisher.

    Args:
        node: the node that owns the subscription.
        msg_type: message class.
        topic: topic name (remappable).
        qos: QoS profile.
    """

    def __init__(self, node: Node, msg_type, topic: str, qos: QoSProfile):
        self._node = node
        libraries = _rcl()
        self.problem = libraries if isinstance(libraries, str) else ""
        self._queue: collections.deque | None = None
        self._checked = False
        if not self.problem:
            self.subscription = node.create_subscription(
                msg_type, topic, lambda _msg: None, qos, callback_group=_NeverExecutedGroup()
            )
            if not hasattr(self.subscription.handle, "pointer"):
                self.problem = "rclpy's subscription handle has no pointer"
                node.destroy_subscription(self.subscription)
        if self.problem:
            self._queue = collections.deque(maxlen=max(1, qos.depth))
            self.subscription = node.create_subscription(msg_type, topic, self._store, qos, raw=True)

    def _store(self, data: bytes) -> None:
        self._queue.append(data)

    @property
    def attributed(self) -> bool:
        """True when messages come with their publisher's GID (:attr:`problem` says why not)."""
        return not self.problem

    @property
    def topic_name(self) -> str:
        """The resolved topic name."""
        return self.subscription.topic_name

    def take(self) -> tuple[bytes | None, bytes] | None:
        """``(publisher GID or None, serialized message)`` of the oldest unread message, or None."""
        if self._queue is not None:
            return (None, self._queue.popleft()) if self._queue else None
        rcl, rcutils = _rcl()
        allocator = rcutils.rcutils_get_default_allocator()
        array = _ByteArray()
        if rcutils.rcutils_uint8_array_init(ctypes.byref(array), 0, ctypes.byref(allocator)) != 0:
            return None
        try:
            info = _MessageInfo()
            handle = self.subscription.handle
            with handle:
                result = rcl.rcl_take_serialized_message(handle.pointer, ctypes.byref(array), ctypes.byref(info), None)
            if result != 0:
                return None  # RCL_RET_SUBSCRIPTION_TAKE_FAILED (401): nothing there; other errors: nothing usable
            gid, data = bytes(info.gid), ctypes.string_at(array.buffer, array.buffer_length)
        finally:
            rcutils.rcutils_uint8_array_fini(ctypes.byref(array))
        if not self._checked:
            # The first sender must be on the graph (it is matched before it delivers): else the
            # GID layout is not the one assumed here, and senders are not told apart.
            self._checked = True
            if gid not in self.publishers():
                self.problem = "the publisher GIDs rcl gives do not match the graph's"
        return (gid if not self.problem else None), data

    def publishers(self) -> dict[bytes, str]:
        """The topic's publishers now: GID -> fully qualified node name (``/ns/name``)."""
        names = {}
        for info in self._node.get_publishers_info_by_topic(self.topic_name):
            namespace = info.node_namespace.rstrip("/")
            names[bytes(info.endpoint_gid)[:GID_SIZE]] = f"{namespace}/{info.node_name}"
        return names

    def destroy(self) -> None:
        """Destroy the subscription."""
        self._node.destroy_subscription(self.subscription)
