"""The Animation Quality Metric (AQM) of Myszkowski et al. 2001 (§2.2, §5.2.3, §6).

Public API: :func:`aqm` (linear RGB pair -> :class:`AQMResult` with M_AQM and d_AQM),
:func:`aqm_luminance` (same for cd/m^2 input), :class:`ViewingConditions`, and
:func:`image_velocity` (per-pixel image velocity from camera motion by 3-D warping).
"""
from __future__ import annotations

from .csf import G_SP
from .display import ViewingConditions
from .flow import image_velocity, pixels_per_frame_to_deg_per_s
from .metric import AQM_SIZE, AQMResult, aqm, aqm_luminance
from .psychometric import P_THRESHOLD

__all__ = ["AQM_SIZE", "AQMResult", "G_SP", "P_THRESHOLD", "ViewingConditions", "aqm", "aqm_luminance",
           "image_velocity", "pixels_per_frame_to_deg_per_s"]
