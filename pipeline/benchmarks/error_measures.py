"""The measures of ``loom bench error``: pure functions over arrays (pipeline/benchmarks/error.py runs them).

Maps are (V, 3) vertex irradiance with (V,) hat-function areas as weights (pipeline/collection/estimators.py);
sequences are over consecutive frames. The error of a frame is a field, e(t) = M(t) - R(t), and its
*flicker* is how much that field changes from one frame to the next, mean_t ||e(t) - e(t-1)|| relative
to the reference: independent per-frame noise flickers by sqrt(2) x its amplitude, an error that
stays put (a temporal method's bias) does not flicker at all. The *lag* after an abrupt lighting
change is read off the step response along the change (see :func:`step_response`).

FLIP (Andersson et al., "FLIP: A Difference Evaluator for Alternating Images", HPG 2020; the
``flip-evaluator`` package, LDR) is computed here for ``loom bench error`` and ``loom bench spp``
alike (:func:`displayed_flip`): both frames of a pair shown with the default look (pipeline/frames/tonemap.py,
filmic) at one adaptation luminance, sRGB-encoded, and compared at the pixels per degree of the AQM's
viewing conditions (pipeline/frames/perceived.py viewing_for), so FLIP and d_AQM judge a frame as one viewer
sees it.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from kernels import colour
from pipeline.errors import LoomError
from pipeline.frames.perceived import viewing_for
from pipeline.frames.tonemap import ToneMapping, display_linear, srgb_encode

if TYPE_CHECKING:
    from collections.abc import Sequence
    from types import ModuleType

    import numpy.typing as npt

LUMA = np.asarray(colour.LUMA)  # Rec. 709 (kernels/colour.py)
LAG_LEVEL = 0.9  # a method has caught up with a change once 90 % of it shows (a rise time)


def _norm(x: np.ndarray, areas: np.ndarray) -> float:
    """Area-weighted L2 norm of a (V, 3) map."""
    return float(np.sqrt(np.sum(areas[:, None] * np.square(x))))


def relative_l2(test: np.ndarray, ref: np.ndarray, areas: np.ndarray) -> float:
    """||test - ref|| / ||ref|| over the surface (area-weighted, RGB)."""
    return _norm(test - ref, areas) / _norm(ref, areas)


def flicker(tests: np.ndarray, refs: np.ndarray, areas: np.ndarray) -> np.ndarray:
    """(T - 1,) ||e(t) - e(t-1)|| / ||R(t)|| of the error fields e = test - ref of frames (T, V, 3);
    ``areas`` (V,) or (T, V)."""
    areas = np.broadcast_to(areas, tests.shape[:2])
    e = tests - refs
    return np.array([_norm(e[t] - e[t - 1], areas[t]) / _norm(refs[t], areas[t]) for t in range(1, len(e))])


def centre_weights(half_width: int, degree: int) -> np.ndarray:
    """(2h + 1,) weights of frames -h..h that give the value at frame 0 of their least-squares
    polynomial of ``degree`` (a mean for degrees 0 and 1; Savitzky and Golay, Anal. Chem. 36, 1964);
    a degree the frames cannot hold is lowered to what they can."""
    if half_width == 0:
        return np.ones(1)
    x = np.arange(-half_width, half_width + 1, dtype=np.float64)
    return np.linalg.pinv(np.vander(x, min(degree, 2 * half_width) + 1, increasing=True))[0]


def symmetric_windows(refs: np.ndarray, half_width: int, degree: int, cut: int | None = None) -> np.ndarray:
    """(T, V, 3) each frame of ``refs`` (T, V, 3) through its symmetric window (:func:`centre_weights`)
    of ``half_width`` frames each side, shortened at the ends and so as never to cross the boundary
    between frames ``cut - 1`` and ``cut``."""
    n = len(refs)
    out = np.empty_like(refs)
    for t in range(n):
        h = min(half_width, t, n - 1 - t)
        if cut is not None:
            h = min(h, cut - 1 - t if t < cut else t - cut)
        out[t] = np.tensordot(centre_weights(h, degree), refs[t - h:t + h + 1], axes=1)
    return out


HINDSIGHT_HALF_WIDTHS = tuple(range(16))  # the windows the bound chooses from: 0-15 frames each side,
HINDSIGHT_DEGREES = (0, 2)  # a mean or a parabola,
HINDSIGHT_BLOCK = 15  # one choice per vertex and this many frame pairs


def hindsight_flicker(refs: np.ndarray, noise_var: np.ndarray, areas: np.ndarray, cut: int | None = None, *,
                      half_widths: Sequence[int] = HINDSIGHT_HALF_WIDTHS,
                      degrees: Sequence[int] = HINDSIGHT_DEGREES, block: int = HINDSIGHT_BLOCK) -> float:
    """A bound on the flicker any choice of windows could have at given photons: RMS over frame pairs
    of ||e(t) - e(t-1)|| / ||R(t)|| when every vertex, in every ``block`` of frame pairs, takes the
    symmetric window (:func:`symmetric_windows` of the lighting ``refs`` (T, V, 3)) whose bias flicker
    plus photon-noise flicker is least there, chosen knowing the lighting. ``noise_var`` (V,) is a
    frame's own photon-noise variance at a vertex (RGB summed); a window's noise flicker is that times
    the sum of squares of its weights' change from one frame to the next. The pair ``cut - 1 | cut``
    (an abrupt change) is left out, and no window crosses it. docs/12-error-benchmark.md §7."""
    n = len(refs)
    areas = np.broadcast_to(areas, refs.shape[:2])
    keep = np.ones(n - 1, bool)
    if cut is not None:
        keep[cut - 1] = False
    weight = areas[1:] / np.array([_norm(refs[t], areas[t]) ** 2 for t in range(1, n)])[:, None]
    blocks = np.arange(n - 1) // block
    best = None
    for degree in degrees:
        for h in half_widths:
            if degree > 1 and 2 * h < degree + 1:  # a polynomial through its own frames: another degree's window
                continue
            bias = symmetric_windows(refs, h, degree, cut) - refs
            w = centre_weights(h, degree)
            step = float(np.sum((np.append(w, 0.0) - np.append(0.0, w)) ** 2))
            cost = (np.sum(np.square(bias[1:] - bias[:-1]), axis=-1) + step * noise_var[None]) * weight
            cost = np.stack([cost[keep & (blocks == k)].sum(axis=0) for k in range(int(blocks.max()) + 1)])
            best = cost if best is None else np.minimum(best, cost)
    return float(np.sqrt(best.sum() / keep.sum()))


def image_flicker(tests: np.ndarray, refs: np.ndarray) -> np.ndarray:
    """(T - 1,) mean |e(t) - e(t-1)| / mean R(t) of displayed frames (T, H, W, 3), e = test - ref."""
    e = tests - refs
    return np.array([np.mean(np.abs(e[t] - e[t - 1])) / np.mean(refs[t]) for t in range(1, len(e))])


def image_errors(test: np.ndarray, ref: np.ndarray) -> tuple[float, float]:
    """(RMSE, mean relative error = mean |test - ref| / mean ref) of two displayed frames (H, W, 3)."""
    d = test - ref
    return float(np.sqrt(np.mean(d * d))), float(np.mean(np.abs(d)) / np.mean(ref))


def relative_rms(test: np.ndarray, ref: np.ndarray) -> float:
    """RMS of the Rec. 709 luminance difference of two linear frames (H, W, 3) over ``ref``'s mean luminance."""
    y_ref = ref @ LUMA
    return float(np.sqrt(np.mean((test @ LUMA - y_ref) ** 2)) / np.mean(y_ref))


def region_energy(irradiance: np.ndarray, areas: np.ndarray, region: np.ndarray) -> float:
    """Luminous flux sum_v A_v Y(E_v) over a set of vertices (the Fig. 3 highlight)."""
    return float(np.sum(areas[region] * (irradiance[region] @ LUMA)))


def brightest_region(ref: np.ndarray, areas: np.ndarray, share: float = 0.02) -> np.ndarray:
    """The vertices of highest indirect luminance holding ``share`` of the surface area: the
    highlight of a scene without a known one."""
    y = ref @ LUMA
    order = np.argsort(-y, kind="stable")
    cum = np.cumsum(areas[order])
    region = np.zeros(len(y), bool)
    region[order[: int(np.searchsorted(cum, share * cum[-1])) + 1]] = True
    return region


def step_response(tests: np.ndarray, refs: np.ndarray, areas: np.ndarray, event: int) -> np.ndarray:
    """How much of the abrupt change at frame index ``event`` each frame from ``event`` on shows.

    The change is D = R(event) - R(event - 1). A frame's response is 1 - <R(t) - M(t), D> / <D, D>
    (area-weighted): 1 when the method shows the reference, 0 when its error is the whole change
    (it still shows the light before the change). Noise orthogonal to D does not move it."""
    w = np.broadcast_to(areas, tests.shape[:2])
    d = refs[event] - refs[event - 1]
    dd = float(np.sum(w[event][:, None] * d * d))
    return np.array([1.0 - float(np.sum(w[t][:, None] * (refs[t] - tests[t]) * d)) / dd
                     for t in range(event, len(tests))])


def lag(response: np.ndarray, level: float = LAG_LEVEL) -> tuple[int, bool]:
    """(frames until the response first reaches ``level``, reached): 0 if the frame of the change
    already shows it; ``len(response)`` and False if no frame of the run does."""
    hit = np.flatnonzero(np.asarray(response) >= level)
    return (int(hit[0]), True) if hit.size else (len(response), False)


def largest_change(refs: np.ndarray, areas: np.ndarray) -> tuple[int, float]:
    """(t, ||R(t) - R(t-1)|| / ||R(t-1)||) of the largest frame-to-frame change of a reference."""
    w = np.broadcast_to(areas, refs.shape[:2])
    steps = [_norm(refs[t] - refs[t - 1], w[t]) / _norm(refs[t - 1], w[t]) for t in range(1, len(refs))]
    t = int(np.argmax(steps))
    return t + 1, float(steps[t])


def loglog(xs: npt.ArrayLike, ys: npt.ArrayLike, x: float) -> tuple[float, bool]:
    """y(x) on the piecewise power law through the points (xs, ys), and whether x lies outside
    them (extrapolated from the nearest segment). Error against time falls as a power of the
    time spent (N^-1/2 for photon noise), so straight lines in log-log are the natural model."""
    xs, ys = np.log(np.asarray(xs, float)), np.log(np.asarray(ys, float))
    order = np.argsort(xs)
    xs, ys = xs[order], ys[order]
    lx = np.log(x)
    if len(xs) == 1:
        return float(np.exp(ys[0])), lx != xs[0]
    i = int(np.clip(np.searchsorted(xs, lx) - 1, 0, len(xs) - 2))
    slope = (ys[i + 1] - ys[i]) / (xs[i + 1] - xs[i]) if xs[i + 1] != xs[i] else 0.0
    return float(np.exp(ys[i] + slope * (lx - xs[i]))), not xs[0] <= lx <= xs[-1]


def cost_model(photons: npt.ArrayLike, times: npt.ArrayLike, slope: float | None = None) -> tuple[float, float]:
    """(a, b) of time = a + b x photons, least squares over a method's runs. Measured times of small
    runs are mostly fixed costs and jitter on a loaded machine; the photons are exact, so a method's
    error is read against its photons and its photons against time through this line. Where the
    jitter makes the fitted slope <= 0, ``slope`` (seconds a photon measured on a larger job, e.g.
    the reference's) is taken instead with a = the mean remainder; without it, a = 0, b = sum t / sum p."""
    p, t = np.asarray(photons, float), np.asarray(times, float)
    b, a = np.polyfit(p, t, 1) if len(p) > 1 and np.ptp(p) > 0 else (0.0, 0.0)
    if not b > 0:
        if slope:
            b = slope
            a = max(float(np.mean(t - b * p)), 0.0)
        else:
            a, b = 0.0, float(t.sum() / p.sum())
    return float(a), float(b)


def equal_time(photons: npt.ArrayLike, times: npt.ArrayLike, errors: npt.ArrayLike, t: float,
               slope: float | None = None) -> tuple[float | None, bool]:
    """A method's error at time ``t`` (None: not even a fixed cost fits in ``t``) and whether it is
    extrapolated: the photons ``t`` buys on its cost line (:func:`cost_model`), their error by :func:`loglog`."""
    a, b = cost_model(photons, times, slope)
    n = (t - a) / b
    if n <= 0:
        return None, True
    return loglog(photons, errors, n)


def equal_error(photons: npt.ArrayLike, times: npt.ArrayLike, errors: npt.ArrayLike, e: float,
                slope: float | None = None) -> tuple[float, bool]:
    """The time a method needs for error ``e``: the photons giving ``e`` (:func:`loglog`) on its cost line."""
    a, b = cost_model(photons, times, slope)
    n, extrapolated = loglog(errors, photons, e)
    return a + b * n, extrapolated


# --- FLIP on frames as their PNGs show them ------------------------------------------------------------
def flip_evaluator() -> ModuleType:
    """The ``flip_evaluator`` module, or a one-line LoomError saying how to install it (test extras)."""
    try:
        import flip_evaluator  # test extra, only for the FLIP measure
    except ImportError:
        raise LoomError("needs NVIDIA FLIP: pip install flip-evaluator (in the test extras: pip install -e '.[test]')",
                        field="flip-evaluator") from None
    return flip_evaluator


def shown(rgb: np.ndarray, adaptation: float) -> np.ndarray:
    """The frame as its PNG shows it: the default look, sRGB-encoded, float in [0, 1] (FLIP's LDR input)."""
    return srgb_encode(display_linear(rgb, adaptation, ToneMapping())).astype(np.float32)


def frame_ppd(width: int, height: int) -> float:
    """Pixels per degree of a ``width`` x ``height`` frame under the AQM's default viewing conditions."""
    return viewing_for(ToneMapping()).frame_ppd((height, width))


def flip_mean(test: np.ndarray, reference: np.ndarray, ppd: float) -> float:
    """Mean FLIP error of two sRGB-encoded LDR images (H, W, 3) in [0, 1] at ``ppd`` pixels per degree."""
    _, mean, _ = flip_evaluator().evaluate(np.ascontiguousarray(reference, np.float32),
                                           np.ascontiguousarray(test, np.float32), "LDR", inputsRGB=True,
                                           applyMagma=False, parameters={"ppd": float(ppd)})
    return float(mean)


def displayed_flip(test: np.ndarray, reference: np.ndarray, adaptation: float, ppd: float) -> float:
    """Mean FLIP error of two linear renderings (H, W, 3) of one frame, both shown at ``adaptation``."""
    return flip_mean(shown(test, adaptation), shown(reference, adaptation), ppd)
