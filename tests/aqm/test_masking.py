"""Contrast masking by a grating against Legge & Foley (1980) (docs/08-aqm.md §9).

Legge & Foley, "Contrast masking in human vision", JOSA 70(12):1458-1471, 1980, measured 2 cy/deg signal
thresholds on 2 cy/deg masking gratings over three log units of masker contrast: for a range of low masker
contrasts thresholds fall below the unmasked one (facilitation), and for high masker contrasts they grow
as a power of masker contrast with exponent near 0.6. So, in units of the unmasked threshold: a masker at
one threshold raises the threshold by no more than about 1x; masking sets in between 1 and 5 thresholds;
from 10 to 30 thresholds the elevation grows by 3^0.6 = 1.9x (exponent 0.5-0.7 accepted); at 30
thresholds it lies between (30/5)^0.6 = 2.9 and 30^0.6 = 7.7.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from modelfest import threshold

from pipeline.aqm import ViewingConditions, aqm_luminance
from pipeline.aqm.masking import threshold_elevation

SIZE, MEAN, CYCLES = 256, 30.0, 22  # 2 cy/deg at 23.3 pixels per degree: 22 whole cycles across 256 pixels
MASKERS = (1, 3, 10, 30)  # masker contrast in unmasked thresholds


@pytest.fixture(scope="module")
def elevation() -> dict[int, float]:
    """AQM threshold of a 2 cy/deg grating on an in-phase 2 cy/deg masker, over the unmasked threshold."""
    viewing = ViewingConditions.for_ppd(2.0 * SIZE / CYCLES)
    grating = np.broadcast_to(np.cos(2 * np.pi * CYCLES * np.arange(SIZE) / SIZE), (SIZE, SIZE))
    centre = slice(SIZE // 4, -SIZE // 4)  # away from the mirrored borders

    def peak(masker):
        def probability(pattern, contrast):
            ref, test = MEAN * (1 + masker * pattern), MEAN * (1 + (masker + contrast) * pattern)
            return float(aqm_luminance(ref, test, viewing=viewing).map[centre, centre].max())
        return probability

    unmasked = threshold(grating, peak(0.0))
    return {k: threshold(grating, peak(k * unmasked)) / unmasked for k in MASKERS}


def test_masker_at_threshold_barely_masks(elevation):
    assert elevation[1] < 1.1


def test_masking_sets_in_between_one_and_five_thresholds(elevation):
    assert elevation[3] < 1.6


def test_power_law_exponent_near_legge_foley(elevation):
    exponent = math.log(elevation[30] / elevation[10]) / math.log(3.0)
    assert 0.5 <= exponent <= 0.7


def test_elevation_at_thirty_thresholds(elevation):
    assert 2.9 <= elevation[30] <= 7.7


def test_daly_constants():
    """k1 = W^(1 - 1/(1-Q)) = 0.0153 and k2 = W^(1/(1-Q)) = 392.5 with W = 6, Q = 0.7: a masker of one
    threshold raises the threshold 6x with learning slope s = 1 and 1.07x with s = 0.65, the AQM's slope."""
    assert float(threshold_elevation(np.array(1.0), s=1.0)) == pytest.approx(6.0, rel=0.01)
    assert float(threshold_elevation(np.array(1.0))) == pytest.approx(1.07, abs=0.01)
    assert float(threshold_elevation(np.array(0.0))) == 1.0
