"""The Animation Quality Metric (AQM) of Myszkowski et al. 2001 (§2.2, §5.2.3, §6).

Public API: :func:`aqm` (linear RGB pair, with the :class:`Motion` of a moving frame -> :class:`AQMResult`
with M_AQM and d_AQM),
:func:`aqm_luminance` (same for cd/m^2 input), :class:`ViewingConditions` (named displays, full-screen
or native frames) with :func:`aqm_geometry` (the pixels per degree a frame and the AQM image have), and
:func:`image_velocity` (per-pixel image velocity from camera motion by 3-D warping).
"""
from __future__ import annotations

from .csf import G_SP
from .display import DISPLAYS, AQMGeometry, ViewingConditions, aqm_geometry, pixels_per_degree
from .flow import image_velocity, pixels_per_frame_to_deg_per_s
from .metric import AQM_SIZE, AQMResult, Motion, aqm, aqm_luminance
from .psychometric import P_THRESHOLD

__all__ = ["AQM_SIZE", "DISPLAYS", "AQMGeometry", "AQMResult", "G_SP", "Motion", "P_THRESHOLD", "ViewingConditions",
           "aqm", "aqm_geometry", "aqm_luminance", "image_velocity", "pixels_per_degree",
           "pixels_per_frame_to_deg_per_s"]
