"""Recorders in the graph, for a client that must not leave before they have its message.

A recorder of all topics (``recorder -p all_topics:=true``, ``ros2 bag record -a``) subscribes a
topic once it discovers a publisher of it; a command-line client's one-shot message can go out
before that. :class:`~manip_kin.pipeline.client.PipelineClient` publishes it latched and waits
for the recorders these functions name. A recorder is a node named ``recorder`` or
``…_recorder`` (manip_kin's ``recorder``, rosbag2's ``rosbag2_recorder``; not, say,
``recorder_test``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

#: Seconds to wait for a recorder's parameter service when asking what it records.
ASK_TIMEOUT_S = 0.5


def recorder_nodes(node) -> set[tuple[str, str]]:
    """``(name, namespace)`` of every recorder node ``node`` sees in the graph."""
    return {
        (name, namespace)
        for name, namespace in node.get_node_names_and_namespaces()
        if name == "recorder" or name.endswith("_recorder")
    }


def recorders_without(node, topic: str, recorders: Iterable[tuple[str, str]]) -> set[tuple[str, str]]:
    """Those of ``recorders`` that have no subscription on ``topic`` (a resolved name) yet."""
    subscribed = {(info.node_name, info.node_namespace) for info in node.get_subscriptions_info_by_topic(topic)}
    return {recorder for recorder in recorders if recorder not in subscribed}


def records_a_list(node, name: str, namespace: str, wait: Callable[[object], object]) -> bool:
    """True for a manip_kin recorder whose ``all_topics`` is false: it subscribed its topics at
    start, so one without a subscription on a topic never will. False when it cannot be asked
    (rosbag2's recorder, or no answer within :data:`ASK_TIMEOUT_S`).

    Args:
        node: the asking node.
        name, namespace: the recorder's.
        wait: ``wait(future)`` spins ``node`` until the future is done (or gives up).
    """
    from rcl_interfaces.msg import ParameterType
    from rcl_interfaces.srv import GetParameters

    client = node.create_client(GetParameters, f"{namespace.rstrip('/')}/{name}/get_parameters")
    try:
        if not client.wait_for_service(timeout_sec=ASK_TIMEOUT_S):
            return False
        future = client.call_async(GetParameters.Request(names=["all_topics"]))
        wait(future)
        if not future.done() or future.result() is None:
            return False
        values = future.result().values
        return bool(values) and values[0].type == ParameterType.PARAMETER_BOOL and not values[0].bool_value
    finally:
        node.destroy_client(client)
