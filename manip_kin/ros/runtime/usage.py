"""The ``--help`` text of a node executable: its parameter table, topics, services and an example."""

from __future__ import annotations

from collections.abc import Sequence

from manip_kin.ros.runtime.params import ParamSpec


def usage_text(
    executable: str,
    summary: str,
    specs: Sequence[ParamSpec],
    subscribes: Sequence[tuple[str, str, str]],
    publishes: Sequence[tuple[str, str, str]],
    example: str,
    extra_help: str = "",
    services: Sequence[tuple[str, str, str]] = (),
) -> str:
    """The ``--help`` text of a node executable.

    Args:
        executable: executable name.
        summary: what the node does (a few lines).
        specs: its parameters.
        subscribes: ``(topic, type, note)`` per input topic.
        publishes: ``(topic, type, note)`` per output topic.
        example: example command line(s).
        extra_help: lines for parameters declared once the model is known (after the table).
        services: ``(name, type, note)`` per service.
    """
    lines = [f"usage: {executable} [--help] [--ros-args -p NAME:=VALUE ... | --params-file FILE | -r FROM:=TO ...]", ""]
    lines += [
        summary.strip(),
        "",
        "Parameters (--ros-args -p NAME:=VALUE or --params-file FILE with /**: ros__parameters;",
        "those marked 'Settable at run time' also with `ros2 param set` on the running node):",
    ]
    lines += [spec.help_line() for spec in specs]
    if extra_help:
        lines.append(extra_help)
    lines += ["", "Subscribes:"]
    lines += [f"  {topic} ({msg_type}){': ' + note if note else ''}" for topic, msg_type, note in subscribes]
    lines += ["", "Publishes:"]
    lines += [f"  {topic} ({msg_type}){': ' + note if note else ''}" for topic, msg_type, note in publishes]
    if services:
        lines += ["", "Services:"]
        lines += [f"  {name} ({srv_type}){': ' + note if note else ''}" for name, srv_type, note in services]
    lines += ["", "Example:", f"  {example}"]
    return "\n".join(lines)
