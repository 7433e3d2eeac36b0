"""Directional light: a direction per frame, static or swept along a sun path.

The direction ``d`` points from the light toward the scene (docs/design.md, "Conventions").
Elevation is the sun's angle above the horizon, azimuth is measured from +Z toward +X about +Y.
The light's colour (linear RGB, white by default; a glTF sun's ``color``) tints the direct term of
the shaded views (:mod:`csmlab.metrics.shading`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csmlab.geometry import normalized

__all__ = ["WHITE", "LightPath", "direction_from_angles"]

WHITE = (1.0, 1.0, 1.0)
"""The colour of a light that names none: the shading's unit irradiance in every channel."""


def direction_from_angles(*, elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    """Unit light direction ``(3,)`` (light toward scene) of a sun at ``elevation_deg`` above the horizon.

    ``elevation_deg = 90`` is a light straight down, ``(0, -1, 0)``.
    """
    if not np.isfinite(elevation_deg) or not -90.0 <= elevation_deg <= 90.0:
        raise ValueError(f"elevation_deg: expected a value in [-90, 90] degrees, got {elevation_deg}")
    if not np.isfinite(azimuth_deg):
        raise ValueError(f"azimuth_deg: expected a finite angle in degrees, got {azimuth_deg}")
    el = np.radians(elevation_deg)
    az = np.radians(azimuth_deg)
    toward_sun = np.array([np.cos(el) * np.sin(az), np.sin(el), np.cos(el) * np.cos(az)])
    return normalized(-toward_sun, name="light direction")


@dataclass(frozen=True)
class LightPath:
    """The light direction of every frame.

    Attributes
    ----------
    directions : ndarray, shape (N, 3), float64
        Unit directions from the light toward the scene, one per frame.
    colour : ndarray, shape (3,), float64
        Linear RGB of the light, each in [0, 1]: the direct light's irradiance is its colour
        times the shading's unit (white ``(1, 1, 1)``, the default, leaves the shading as it was).
    """

    directions: np.ndarray
    colour: np.ndarray = WHITE

    def __post_init__(self) -> None:
        d = normalized(np.atleast_2d(self.directions), name="light direction")
        d.setflags(write=False)
        object.__setattr__(self, "directions", d)
        c = np.array(self.colour, dtype=np.float64)
        if c.shape != (3,) or not np.all((c >= 0.0) & (c <= 1.0)):
            raise ValueError(f"light colour: expected three linear RGB values in [0, 1], got {self.colour!r}")
        c.setflags(write=False)
        object.__setattr__(self, "colour", c)

    @classmethod
    def static(cls, direction, frames: int) -> LightPath:
        """The same ``direction`` for ``frames`` frames."""
        return cls(np.repeat(normalized(direction, name="light direction")[None], frames, axis=0))

    @classmethod
    def sun(cls, *, elevation_deg: float, azimuth_deg: float, elevation_end_deg: float,
            azimuth_end_deg: float, frames: int) -> LightPath:
        """A sun moving linearly in elevation and azimuth from the first frame to the last."""
        s = np.linspace(0.0, 1.0, frames) if frames > 1 else np.zeros(1)
        return cls(np.stack([
            direction_from_angles(
                elevation_deg=elevation_deg + f * (elevation_end_deg - elevation_deg),
                azimuth_deg=azimuth_deg + f * (azimuth_end_deg - azimuth_deg),
            )
            for f in s
        ]))

    def __len__(self) -> int:
        return self.directions.shape[0]

    def direction(self, frame: int) -> np.ndarray:
        """Unit direction ``(3,)`` at ``frame``."""
        return self.directions[frame]

    @property
    def is_static(self) -> bool:
        """True when every frame has the same direction bit for bit."""
        return bool(np.all(self.directions == self.directions[0]))
