"""Errors of the recording tools; each says what was received and what is valid."""

from __future__ import annotations

from manip_kin.errors import ManipKinError


class RecordingError(ManipKinError):
    """A recording (MCAP file or bag directory) that cannot be read or written."""


class CorruptRecordingError(RecordingError):
    """A file that is not a complete MCAP recording (garbage, or truncated by a kill)."""


class MessageDefinitionError(RecordingError):
    """A message type whose ``.msg`` definition or Python class cannot be found."""
