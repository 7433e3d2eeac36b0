"""Checks on generator keywords, with messages that name the keyword and what was expected."""

from __future__ import annotations

import math
import numbers

__all__ = ["count", "non_negative", "positive"]


def positive(value, *, field: str) -> float:
    """``value`` as a float after checking it is finite and > 0; ``ValueError`` names ``field``."""
    if not isinstance(value, numbers.Real) or not math.isfinite(value) or value <= 0:
        raise ValueError(f"{field}: expected a finite number > 0, got {value!r}")
    return float(value)


def non_negative(value, *, field: str) -> float:
    """``value`` as a float after checking it is finite and ≥ 0; ``ValueError`` names ``field``."""
    if not isinstance(value, numbers.Real) or not math.isfinite(value) or value < 0:
        raise ValueError(f"{field}: expected a finite number ≥ 0, got {value!r}")
    return float(value)


def count(value, *, field: str, minimum: int = 0) -> int:
    """``value`` as an int after checking it is a whole number ≥ ``minimum``; ``ValueError`` names ``field``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < minimum:
        raise ValueError(f"{field}: expected a whole number ≥ {minimum}, got {value!r}")
    return int(value)
