"""The Animation Quality Metric: two renderings of a frame in, M_AQM and d_AQM out (§2.2, §5.2.3, §6).

Stages (one module each): display luminance and resampling to ``aqm_size`` with the viewing distance
scaled so visual angles, hence spatial frequencies, are kept (display.py, §6) -> Daly's nonlinearity
with local adaptation (nonlinearity.py) -> CSF with per-pixel adaptation luminance and retinal velocity
(csf.py) -> Daly's cortex transform (bands.py): the difference in 31 radial x orientation channels, each
image in six radial bands for masking -> mutual masking without orientation (masking.py, §6) ->
psychometric function and probability summation over the 31 channels (psychometric.py) -> M_AQM
(per-pixel detection probability) and d_AQM (% of pixels with P > 0.75, i.e. above 1 JND).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..config import AQM_SIZE
from ..errors import LoomError
from .bands import decompose, decompose_channels
from .csf import (
    G_SP,
    luminance_bank,
    luminance_coordinate,
    retinal_velocity,
    space_variant_filter,
    velocity_bank,
    velocity_coordinate,
)
from .display import (
    ViewingConditions,
    aqm_geometry,
    check_image,
    check_luminance,
    display_luminance,
    relative_luminance,
    resample,
)
from .masking import mutual_masking
from .nonlinearity import local_adaptation, nonlinear_contrast
from .psychometric import P_THRESHOLD, d_aqm, detection_probability

# Every filter works by FFT, which treats the image as periodic: the left border would meet the right one
# and the (usually large) luminance step there would mask errors along the borders. Mirroring a margin
# of a quarter of the longer side around the image makes the borders continuous [decision]; at 256 px
# this costs about 2x the time of the unpadded 256 x 256 FFTs.
PAD_FRACTION = 0.25


@dataclass(frozen=True)
class AQMResult:
    """M_AQM (``map``: detection probability per pixel at the AQM resolution) and d_AQM (percent)."""

    map: np.ndarray
    d_aqm: float
    ppd: float  # pixels per degree of ``map`` (display ppd scaled with the resampling)
    threshold: float = P_THRESHOLD

    @property
    def visible(self) -> np.ndarray:
        """Pixels where a difference is predicted visible (P > threshold, 1 JND)."""
        return self.map > self.threshold


@dataclass(frozen=True)
class Motion:
    """How the image moves and how the eye follows it (§6): ``flow``, the image velocity in deg/s of
    frame pixels, (H, W, 2) vectors or (H, W) speeds, from camera motion (flow.py); ``pursuit_gain``,
    the eye's smooth-pursuit gain for it (0.82 Daly 1998; 0 = not followed, 1 = fully tracked);
    ``name`` labels the flow in error messages."""

    flow: npt.ArrayLike
    pursuit_gain: float = G_SP
    name: str = "flow"

    def __post_init__(self) -> None:
        if not 0.0 <= self.pursuit_gain <= 1.0:
            raise LoomError(f"must lie in [0, 1], got {self.pursuit_gain!r}", field="pursuit_gain")


def aqm(image_a: npt.ArrayLike, image_b: npt.ArrayLike, *, motion: Motion | None = None,
        viewing: ViewingConditions = ViewingConditions(), aqm_size: int = AQM_SIZE,
        names: tuple[str, str] = ("A", "B")) -> AQMResult:
    """Predict visible differences between two linear-RGB renderings of one frame.

    ``image_a``/``image_b``: (H, W, 3|4) linear Rec.709 RGB (or (H, W) relative luminance); 1.0 is the
    display's peak white (ViewingConditions). ``motion``: the frame's image motion; None for a still
    frame. ``names`` label the inputs in error messages. Symmetric in a and b.
    """
    a = check_image(image_a, names[0])
    b = check_image(image_b, names[1])
    _check_same_size(a, b, names)
    lum_a = display_luminance(relative_luminance(a), viewing, names[0])
    lum_b = display_luminance(relative_luminance(b), viewing, names[1])
    return aqm_luminance(lum_a, lum_b, motion=motion, viewing=viewing, aqm_size=aqm_size, names=names)


def aqm_luminance(lum_a: npt.ArrayLike, lum_b: npt.ArrayLike, *, motion: Motion | None = None,
                  viewing: ViewingConditions = ViewingConditions(), aqm_size: int = AQM_SIZE,
                  names: tuple[str, str] = ("A", "B")) -> AQMResult:
    """:func:`aqm` for inputs already in display luminance, cd/m^2 (H, W); viewing gives only the geometry."""
    lum_a = check_image(lum_a, names[0])
    lum_b = check_image(lum_b, names[1])
    _check_same_size(lum_a, lum_b, names)
    for lum, name in ((lum_a, names[0]), (lum_b, names[1])):
        if lum.ndim != 2:
            raise LoomError(f"expected a luminance image (H, W), got {lum.shape}", path=name, field="shape")
        check_luminance(lum, name)
    if not (isinstance(aqm_size, int) and aqm_size >= 16):
        raise LoomError(f"must be an integer >= 16, got {aqm_size!r}", field="aqm_size")

    full = lum_a.shape
    # Scaling the image and the viewing distance together keeps every visual angle (§6).
    geometry = aqm_geometry(viewing, full, aqm_size)
    shape, ppd, i2 = geometry.shape, geometry.ppd, geometry.image_area_deg2
    pad = int(round(PAD_FRACTION * max(shape)))
    lum_a, lum_b = _mirror(resample(lum_a, shape), pad), _mirror(resample(lum_b, shape), pad)
    work = lum_a.shape

    adaptation = local_adaptation(lum_a, lum_b, ppd)
    stages = []
    if motion is not None:
        flow = _check_flow(motion.flow, full, motion.name)
        v_r = retinal_velocity(_mirror(resample(flow, shape), pad), motion.pursuit_gain)
        stages.append((velocity_bank(work, ppd), velocity_coordinate(v_r)))
    # Daly's accommodation term r_a takes the distance the eye is focused at, the real one: §6 scales the
    # distance only "to preserve the same spatial frequencies", which the scaled ppd already does.
    stages.append((luminance_bank(work, ppd, i2, viewing.viewing_distance_m), luminance_coordinate(adaptation)))

    spectrum_a = _csf_spectrum(nonlinear_contrast(lum_a, adaptation), work, stages)
    spectrum_b = _csf_spectrum(nonlinear_contrast(lum_b, adaptation), work, stages)
    # Masking is computed on the radial bands, without orientation (§6 of the paper); detection uses
    # all of Daly's channels, and by linearity the channels of the difference are the difference of channels.
    elevation = mutual_masking(decompose(spectrum_a, work), decompose(spectrum_b, work))
    delta, band = decompose_channels(spectrum_b - spectrum_a, work)
    probability = detection_probability(delta, elevation, band=band)[pad:pad + shape[0], pad:pad + shape[1]]
    return AQMResult(map=probability, d_aqm=d_aqm(probability), ppd=float(ppd))


def _mirror(image: np.ndarray, pad: int) -> np.ndarray:
    """``image`` with ``pad`` mirrored rows and columns on every side (first two axes)."""
    widths = ((pad, pad), (pad, pad)) + ((0, 0),) * (image.ndim - 2)
    return np.pad(image, widths, mode="symmetric")


def _csf_spectrum(contrast: np.ndarray, shape: tuple[int, int], stages) -> np.ndarray:
    """rfft2 of the CSF-weighted contrast (threshold units): each stage is a per-pixel filter bank."""
    spectrum = np.fft.rfft2(contrast)
    for bank, coord in stages:
        filtered, image = space_variant_filter(spectrum, shape, bank, coord)
        spectrum = filtered if image is None else np.fft.rfft2(image)
    return spectrum


def _check_same_size(a: np.ndarray, b: np.ndarray, names) -> None:
    if a.shape[:2] != b.shape[:2]:
        raise LoomError(f"image sizes differ: {a.shape[1]}x{a.shape[0]} vs {b.shape[1]}x{b.shape[0]}",
                        path=names[1], field="size")


def _check_flow(flow, shape: tuple[int, int], name: str) -> np.ndarray:
    f = np.asarray(flow, dtype=np.float64)
    if f.shape[:2] != tuple(shape) or not (f.ndim == 2 or (f.ndim == 3 and f.shape[2] == 2)):
        raise LoomError(f"expected shape {shape} or {shape + (2,)} to match the images, got {f.shape}",
                        path=name, field="shape")
    if not np.all(np.isfinite(f)):
        raise LoomError("NaN or Inf velocity", path=name, field="pixels")
    if f.ndim == 2 and (f < 0).any():
        raise LoomError("negative speed in a one-channel flow", path=name, field="pixels")
    return f
