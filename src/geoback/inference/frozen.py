"""Frozen results all the way down: the arrays a frozen result holds are read-only copies, so that
neither the result's reader nor the code that built it can change it afterwards (derived values
are new results, made with ``dataclasses.replace``)."""
from __future__ import annotations

import numpy as np


def readonly(a):
    """A read-only copy of the array `a` (None stays None; dtype kept)."""
    if a is None:
        return None
    a = np.array(a)
    a.setflags(write=False)
    return a
