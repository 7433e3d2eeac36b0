"""Where each shadow cascade lies: split schemes, bounds, fit modes, extents, stabilization, and the CascadeSet."""

from csmlab.cascades.bounds import BOUNDS_METHODS, DEPTH_RANGE_METHODS
from csmlab.cascades.cascade_set import Cascade, CascadeSet, build_cascades, tight_extents
from csmlab.cascades.extent import EXTENT_METHODS
from csmlab.cascades.fit import FIT_METHODS
from csmlab.cascades.splits import SPLIT_METHODS, split_distances
from csmlab.cascades.stabilize import SNAP_METHODS, STABILIZATION_METHODS

__all__ = ["BOUNDS_METHODS", "DEPTH_RANGE_METHODS", "EXTENT_METHODS", "FIT_METHODS", "SNAP_METHODS", "SPLIT_METHODS",
           "STABILIZATION_METHODS", "Cascade", "CascadeSet", "build_cascades", "split_distances", "tight_extents"]
