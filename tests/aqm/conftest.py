"""Fixtures for the AQM tests."""
from __future__ import annotations

import numpy as np
import pytest
from aqm_data import GRATING_PPD, SIZE

from pipeline.aqm import ViewingConditions


@pytest.fixture(scope="session")
def grating_viewing() -> ViewingConditions:
    return ViewingConditions.for_ppd(GRATING_PPD)


@pytest.fixture(scope="session")
def shaded_scene() -> np.ndarray:
    """Noise-free linear-RGB frame: a lit gradient with soft stripes, like diffuse indirect lighting."""
    yy, xx = np.mgrid[0:SIZE, 0:SIZE] / SIZE
    y = 0.2 + 0.6 * xx * (0.5 + 0.5 * yy) + 0.1 * np.sin(2 * np.pi * 4 * yy)
    return np.stack([y * 1.1, y, y * 0.8], axis=2)
