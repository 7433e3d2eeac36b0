"""Where each shadow cascade lies: split schemes, fit modes, stabilization, and the CascadeSet."""

from csmlab.cascades.cascade_set import Cascade, CascadeSet, build_cascades
from csmlab.cascades.fit import FIT_METHODS
from csmlab.cascades.splits import SPLIT_METHODS, split_distances
from csmlab.cascades.stabilize import STABILIZATION_METHODS

__all__ = ["FIT_METHODS", "SPLIT_METHODS", "STABILIZATION_METHODS", "Cascade", "CascadeSet", "build_cascades",
           "split_distances"]
