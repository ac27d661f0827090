"""The one exception of the pipeline tools."""

from __future__ import annotations

from manip_kin.errors import ManipKinError


class PipelineError(ManipKinError):
    """A node that did not start, died, or a wait that timed out."""
