"""What the viewer sees of a rendering: display values after this render's tone mapping (§5.2.3).

The AQM predicts visible differences between two *displayed* frames (Daly 1993 takes cd/m^2), so
the even/odd renderings I1(K), I2(K) are compared after the tone mapping and eye adaptation the
final frame gets (pipeline/tonemap.py): L_d = m(L_wa) L_w, clipped at the display's white
Ld_max. Comparing linear radiance as if 1.0 were 100 cd/m^2 instead judges a dim room as a bright
one (sensitivity rises with luminance) and never clips highlights, so it over-states the noise.
"""
from __future__ import annotations

import numpy as np

from .aqm import AQMResult, ViewingConditions, aqm
from .tonemap import ToneMapping, ward_scale


def display_values(rgb: np.ndarray, adaptation: float, params: ToneMapping = ToneMapping()) -> np.ndarray:
    """Linear display values (1.0 = the display's white, Ld_max) of linear radiance ``rgb`` shown at
    adaptation luminance ``adaptation`` (radiance units): the PNG's value before its sRGB encoding."""
    m = ward_scale(adaptation * params.nits_per_unit, params.display_max)
    return np.clip(np.asarray(rgb, np.float64) * (params.nits_per_unit * m / params.display_max), 0.0, 1.0)


def viewing_for(params: ToneMapping) -> ViewingConditions:
    """The AQM's viewing conditions with the display white the tone mapping maps to."""
    return ViewingConditions(peak_luminance=params.display_max)


def displayed_difference(rgb_a: np.ndarray, rgb_b: np.ndarray, adaptation: float, *,
                         params: ToneMapping = ToneMapping(), aqm_size: int = 256) -> AQMResult:
    """d_AQM and M_AQM of two linear renderings of one frame as the viewer sees them."""
    view = viewing_for(params)
    return aqm(display_values(rgb_a, adaptation, params), display_values(rgb_b, adaptation, params),
               viewing=view, aqm_size=aqm_size, names=("I1", "I2"))
