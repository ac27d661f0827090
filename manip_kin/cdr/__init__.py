"""CDR (XCDR1), the byte layout ROS 2 messages travel and are recorded in: the one codec's
primitives, shared by the nodes' pre-serialised messages (:mod:`manip_kin.ros.wire.cdr`) and
the recordings' TF messages (:mod:`manip_kin.recording.tf_message`). No ROS here."""

from manip_kin.cdr.primitives import CDR_LE, CdrLayout, CdrReader, CdrWriter, align, stamp_parts

__all__ = ["CDR_LE", "CdrLayout", "CdrReader", "CdrWriter", "align", "stamp_parts"]
