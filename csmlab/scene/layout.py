"""Where the default camera paths go, and so where procedural scenes must leave room.

The camera-path generators keep within 40 m of the origin at eye height ≥ 1.5 m; ``walk`` circles
the origin at 20 m. Every procedural scene therefore keeps

* its ground within ±0.3 m of ``y = 0`` inside 45 m of the origin (the camera height above the
  ground is then what the path says), and
* a clear ring road ``20 ± 2 m`` from the origin and a clear disc of radius 4 m at the origin:
  no caster rises above 0.3 m over either,

while placing plenty of casters 2–15 m from the ring so the near cascades have shadows to flicker.
Distances are horizontal (in the x–z plane), metres.
"""

from __future__ import annotations

import numpy as np

__all__ = ["CLEARANCE", "CLEAR_DISC_RADIUS", "FLAT_RADIUS", "FLAT_TOLERANCE", "RING_HALF_WIDTH", "RING_RADIUS",
           "clear_of_camera"]

RING_RADIUS = 20.0
"""Radius of the ``walk`` path's circle, metres."""
RING_HALF_WIDTH = 2.0
"""Half width of the clear ring road, metres."""
CLEAR_DISC_RADIUS = 4.0
"""Radius of the clear disc at the origin, metres."""
FLAT_RADIUS = 45.0
"""Inside this horizontal distance the ground stays within :data:`FLAT_TOLERANCE` of ``y = 0``, metres."""
FLAT_TOLERANCE = 0.3
"""Allowed ground height (±) inside :data:`FLAT_RADIUS`, and the most a caster may rise over a clear zone, metres."""
CLEARANCE = 0.25
"""Extra gap generators leave between a caster's footprint and a clear zone, metres."""


def clear_of_camera(x, z, *, radius) -> np.ndarray:
    """Whether discs of ``radius`` at ``(x, z)`` stay off the clear ring and disc, with :data:`CLEARANCE`.

    Parameters
    ----------
    x, z : array_like, shape (N,)
        Footprint centres, world metres.
    radius : array_like, shape (N,) or scalar
        Footprint radius (bounding circle of the caster seen from above), metres.

    Returns
    -------
    ndarray, shape (N,), bool
        True where the footprint touches neither zone.
    """
    r = np.hypot(np.asarray(x, dtype=np.float64), np.asarray(z, dtype=np.float64))
    reach = np.asarray(radius, dtype=np.float64) + CLEARANCE
    off_disc = r - reach >= CLEAR_DISC_RADIUS
    off_ring = (r + reach <= RING_RADIUS - RING_HALF_WIDTH) | (r - reach >= RING_RADIUS + RING_HALF_WIDTH)
    return off_disc & off_ring
