"""The natural-coordinate model of a scene: index arrays (:mod:`.build`), the constraint
equations written once (:mod:`.equations`), degrees of freedom and redundancy (:mod:`.mobility`)."""
from ..cache import derived
from .build import Model, build_model, content_key, driver_scale, driver_values
from .rows import _R90
from .mobility import Mobility, check_mobility, constraint_source, generic_mobility, mobility

__all__ = ["Model", "_R90", "derived", "build_model", "content_key", "driver_scale", "driver_values", "Mobility", "check_mobility",
           "constraint_source", "generic_mobility", "mobility"]
