"""What a closed recording holds (:class:`RecordingSummary`), and sizes in human units."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class RecordingSummary:
    """What a closed recording holds.

    Attributes:
        path: the bag directory, or the ``.mcap`` file.
        mcap_path: the MCAP file.
        topic_counts: messages per topic (topics without messages included).
        message_count: all messages.
        message_bytes: CDR bytes of all messages (before compression).
        file_bytes: size of the MCAP file.
        start_ns, end_ns: first and last receive time, ns since the epoch (0 when empty).
    """

    path: Path
    mcap_path: Path
    topic_counts: dict[str, int]
    message_count: int
    message_bytes: int
    file_bytes: int
    start_ns: int
    end_ns: int

    @property
    def duration_s(self) -> float:
        """Seconds between the first and last message."""
        return (self.end_ns - self.start_ns) / 1e9 if self.message_count else 0.0

    def one_line(self) -> str:
        """``recorded 3 topics, 1200 messages, 56.1 KiB in 1.20 s to runs/x.mcap``."""
        return (
            f"recorded {len(self.topic_counts)} topics, {self.message_count} messages, "
            f"{format_bytes(self.file_bytes)} in {self.duration_s:.2f} s to {self.path}"
        )


def format_bytes(size: int) -> str:
    """Human size with binary units (``1.5 MiB``)."""
    value = float(size)
    for unit in ("B", "KiB", "MiB", "GiB"):
        if value < 1024 or unit == "GiB":
            return f"{value:.0f} {unit}" if unit == "B" else f"{value:.1f} {unit}"
        value /= 1024
    return f"{size} B"
