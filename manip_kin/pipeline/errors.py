"""The one exception of the pipeline tools."""

from __future__ import annotations

from manip_kin.errors import OperationError


class PipelineError(OperationError):
    """A node that did not start, died, or a wait that timed out."""
