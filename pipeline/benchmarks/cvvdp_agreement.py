"""The AQM beside ColorVideoVDP on element-scale noise: the amplitude at which each first calls it visible.

Bench-only: needs PyTorch and ``cvvdp`` (PyPI), which stay out of the project's dependencies and tests.
Run in a separate environment that has them and NumPy, from the repository root:

    PYTHONPATH=. /path/to/venv/bin/python -m pipeline.benchmarks.cvvdp_agreement

Stimulus: a 320 x 240 frame (ROOM's default size), flat grey or a smooth random texture, multiplied by
1 + a n(x, y), where n is unit-variance Gaussian noise drawn at the vertices of a grid of 8-pixel
elements and interpolated bilinearly between them (the look of per-vertex photon estimates shaded across
mesh elements). Both metrics see the frame full screen on ColorVideoVDP's "standard_fhd" display (24-inch
1920 x 1080 at 0.6 m, 200 cd/m^2): the AQM through ViewingConditions.named("standard_fhd"), ColorVideoVDP
on the frame scaled by 4.5 (pixel replication) to 1440 x 1080. Criteria: the AQM calls a difference
visible where P > 0.75 (any pixel: max P > 0.75; and d_AQM >= 1 %, the paper's quality bound);
ColorVideoVDP where its quality falls 1 JOD below 10 (1 JOD = 75 % preference, about one JND), and,
stricter, 0.5 JOD. The amplitude a is bisected in log space for each criterion.
"""
from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from pipeline.aqm import ViewingConditions, aqm

H, W, ELEMENT, SCALE = 240, 320, 8, 4.5


def element_noise(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    gy, gx = H // ELEMENT + 1, W // ELEMENT + 1
    vertices = rng.standard_normal((gy, gx))
    y = np.arange(H) / ELEMENT
    x = np.arange(W) / ELEMENT
    y0, x0 = np.minimum(y.astype(int), gy - 2), np.minimum(x.astype(int), gx - 2)
    fy, fx = (y - y0)[:, None], (x - x0)[None, :]
    v = vertices
    field = ((1 - fy) * (1 - fx) * v[y0][:, x0] + (1 - fy) * fx * v[y0][:, x0 + 1]
             + fy * (1 - fx) * v[y0 + 1][:, x0] + fy * fx * v[y0 + 1][:, x0 + 1])
    return field / field.std()


def surfaces() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(7)
    spectrum = np.fft.rfft2(rng.standard_normal((H, W)))
    fy = np.fft.fftfreq(H)[:, None]
    fx = np.fft.rfftfreq(W)[None, :]
    smooth = np.fft.irfft2(spectrum * np.exp(-2 * np.pi**2 * 1.5**2 * (fx**2 + fy**2)), s=(H, W))
    texture = np.exp(0.5 * smooth / smooth.std())
    return {"flat": np.full((H, W), 0.2), "textured": 0.2 * texture / texture.mean()}


def srgb(linear: np.ndarray) -> np.ndarray:
    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def bisect(visible: Callable[[float], bool], lo: float = 1e-3, hi: float = 0.5, steps: int = 12) -> float:
    """Smallest amplitude in [lo, hi] that ``visible`` accepts (log bisection); nan if hi is not visible."""
    if not visible(hi):
        return math.nan
    for _ in range(steps):
        mid = math.sqrt(lo * hi)
        lo, hi = (lo, mid) if visible(mid) else (mid, hi)
    return hi


def main() -> None:
    # Optional heavy dependencies of a bench-only environment (PyTorch, cvvdp): never the project's
    import pycvvdp  # bench-only environment
    import torch

    torch.set_num_threads(1)
    metric = pycvvdp.cvvdp(display_name="standard_fhd", device=torch.device("cpu"))
    viewing = ViewingConditions.named("standard_fhd")
    noise = element_noise(1)
    for name, surface in surfaces().items():
        def test(a, surface=surface):
            return np.clip(surface * (1 + a * noise), 0, None)

        def aqm_any(a, surface=surface):
            return float(aqm(surface, test(a), viewing=viewing).map.max()) > 0.75

        def aqm_one_percent(a, surface=surface):
            return aqm(surface, test(a), viewing=viewing).d_aqm >= 1.0

        def jod(a, surface=surface):
            big = lambda img: np.kron(srgb(img), np.ones((int(SCALE * 2), int(SCALE * 2))))[::2, ::2]  # noqa: E731
            ref = torch.tensor(np.repeat(big(surface)[..., None], 3, axis=2), dtype=torch.float32)
            tst = torch.tensor(np.repeat(big(test(a))[..., None], 3, axis=2), dtype=torch.float32)
            q, _ = metric.predict(tst, ref, dim_order="HWC")
            return float(q)

        results = {
            "AQM max P > 0.75": bisect(aqm_any),
            "AQM d_AQM >= 1 %": bisect(aqm_one_percent),
            "ColorVideoVDP 1 JOD": bisect(lambda a: jod(a) <= 9.0),
            "ColorVideoVDP 0.5 JOD": bisect(lambda a: jod(a) <= 9.5),
        }
        print(f"{name}: " + "; ".join(f"{k} at a = {v:.4f}" for k, v in results.items()), flush=True)


if __name__ == "__main__":
    main()
