"""Material conventions shared by the Blender exporter and the USD reader."""

import math


def specular_layer_ior(ior, level):
    """IOR of the dielectric specular layer for a Specular IOR Level (0.5 keeps the IOR,
    0 removes the layer): normal-incidence reflectance F0 = ((η−1)/(η+1))² scaled by 2·level,
    as Cycles does for Principled."""
    if ior <= 0.0:
        return 1.0
    r = min(math.sqrt(((ior - 1.0) / (ior + 1.0)) ** 2 * 2.0 * min(max(level, 0.0), 1.0)), 0.999)
    return (1.0 + r) / (1.0 - r)
