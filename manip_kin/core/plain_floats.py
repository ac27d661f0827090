"""Vectors as lists of Python floats, for code that runs every control cycle.

For a handful of joints, numpy's per-call overhead costs more than the arithmetic (and at
1 kHz the caches are cold between cycles, which makes each call dearer still); the per-cycle
functions loop over plain floats instead. One conversion for all of them.
"""

from __future__ import annotations

import numpy as np


def float_list(values) -> list:
    """``values`` as a list of floats: an ndarray's ``tolist()``, a list as it is, any other
    sequence converted element by element."""
    if type(values) is np.ndarray:
        return values.tolist()
    return values if type(values) is list else [float(v) for v in values]
