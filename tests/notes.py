"""How far a number of ``zswarm sim`` may be from a number READING-NOTES prints, and why.

READING-NOTES prints its numbers to one or two significant figures ("≈ 2.1", "≈ 0.08",
"≈ 1e-2").  A printed x stands for the interval of numbers that print as x: [x − h⁻, x + h)
with h half a unit of its last figure, and h⁻ = h/10 when x is a power of ten (0.0095 prints
as 1e-2 too).  Its integration (Lie–Euler at 1 ms) and ours (agents at 100 Hz, sensors at
200 Hz) are first-order discretisations of the same equations, so each number also carries
the distance of each step to dt → 0: ``step``, per scenario and time, is twice the distance
measured between our default rates and the same scenario at 10x the rates
(zswarm.studies.step_size.refine: agents 1 kHz, sensors 2 kHz), which bounds the notes' own finer step
too (measured 2026-12-05, see each use).  At t = 0 nothing has been stepped: ``step`` = 0.
"""

from __future__ import annotations

import math


def interval(printed: str, step: float) -> tuple[float, float]:
    """The numbers READING-NOTES' ``printed`` may stand for, widened by ``step`` (relative)."""
    x = float(printed)
    mantissa = printed.lower().split("e")[0].lstrip("-")
    decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
    exp = int(printed.lower().split("e")[1]) if "e" in printed.lower() else 0
    h = 0.5 * 10.0 ** (exp - decimals)
    digits = mantissa.replace(".", "").lstrip("0")
    lo_h = h / 10 if digits == "1" else h  # a power of ten: the decade below rounds up to it
    return (x - lo_h) * (1.0 - step), (x + h) * (1.0 + step)


def agrees(got: float, printed: str, step: float) -> bool:
    """``got`` within :func:`interval` of the printed number."""
    lo, hi = interval(printed, step)
    return math.isfinite(got) and lo <= got < hi
