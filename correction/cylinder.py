"""Moved to :mod:`arm_model.geometry` (one geometry module for every fit); this alias goes soon."""
from arm_model.geometry import (CircleFit, CylinderFit, RingFit, fit_circle_2d, fit_cylinder,  # noqa: F401
                                fit_row_circles, kasa_circle, ring_fit, split_rows)
