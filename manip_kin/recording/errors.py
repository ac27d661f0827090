"""Errors of the recording tools; each says what was received and what is valid."""

from __future__ import annotations

from manip_kin.errors import InputError


class RecordingError(InputError):
    """A recording (MCAP file or bag directory) or recording option that cannot be used as given."""


class CorruptRecordingError(RecordingError):
    """A file that is not a complete MCAP recording (garbage, or truncated by a kill)."""


class MessageDefinitionError(RecordingError):
    """A message type whose ``.msg`` definition or Python class cannot be found."""
