"""Gather (§4, §5.2.4): element sums, window sums and vertex flux on PoCL (element_sums_cl,
frame_sums_flux_cl: the path pipeline/collection/maps.py runs) equal their NumPy twins within 1e-6
relative, a one-frame window is pipeline/collection/estimators.py's vertex_irradiance, and repeated runs are
bitwise identical."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from kernels.gather import (
    element_sums_cl,
    element_sums_reference,
    frame_sums_flux_cl,
    irradiance,
    window_flux_reference,
)
from pipeline.collection.estimators import vertex_irradiance
from tests.kernels.twin_base import KernelTwinTests

RTOL = 1e-6


def frame_records(rng, n_records, n_elements, *, hit=None, energy_scale=1.0):
    """Element-sorted random records; ``hit`` restricts the elements that get photons."""
    pool = np.arange(n_elements) if hit is None else np.asarray(hit)
    element = np.sort(rng.choice(pool, n_records)) if n_records and len(pool) else np.zeros(0, np.int64)
    key = (element.astype(np.uint32) | rng.integers(0, 2, n_records).astype(np.uint32) << np.uint32(30)
           | rng.integers(0, 2, n_records).astype(np.uint32) << np.uint32(31))
    b1 = rng.integers(0, 32768, n_records).astype(np.uint16)
    b2 = (rng.random(n_records) * (65535 - b1)).astype(np.uint16)
    energy = (rng.random((n_records, 3)) * energy_scale).astype(np.float32)
    offsets = np.concatenate([[0], np.cumsum(np.bincount(element, minlength=n_elements))])
    return SimpleNamespace(key=key, b1=b1, b2=b2, energy=energy, offsets=offsets,
                           element=element, direct=(key >> 31).astype(bool))


def mesh(rng, n_elements, n_vertices):
    ev = np.stack([rng.choice(n_vertices, 3, replace=False) for _ in range(n_elements)]).astype(np.int32)
    return ev


def stacked_flux_cl(sums, *args):
    """frame_sums_flux_cl over the frames of a (J, E, P, 3, 4) element sums table."""
    return frame_sums_flux_cl(list(sums), *args)


def close(a, b):
    np.testing.assert_allclose(a, b, rtol=RTOL, atol=RTOL * max(1e-300, float(np.abs(b).max(initial=0))))


def _close_rule(want):
    """(rtol, atol) of the gather's comparisons: 1e-6 relative, absolute 1e-6 of the largest value."""
    return RTOL, RTOL * max(1e-300, float(np.abs(want).max(initial=0)))


class TestElementSumsTwin(KernelTwinTests):
    """``element_sums`` (gather.cl) against :func:`element_sums_reference` within 1e-6."""

    KINDS = ("indirect", "direct", "all")
    # (frames' records, kind, split parity)
    cases = {**{f"mixed-{kind}-{'split' if split else 'whole'}": ("mixed", kind, split)
                for kind in KINDS for split in (False, True)},
             **{f"{name}-all-split": (name, "all", True)
                for name in ("huge", "tiny", "never hit", "one record", "no records", "no elements")}}

    def make_inputs(self, rng, case):
        name, kind, split = case
        if name == "mixed":
            frames = [frame_records(rng, int(rng.integers(0, 4000)), 300) for _ in range(7)]
            frames.append(frame_records(rng, 0, 300))  # a frame without records
            frames.append(frame_records(rng, 500, 300, hit=[7]))  # every photon in one element
        else:
            frames = [{
                "huge": lambda: frame_records(rng, 3000, 50, energy_scale=3e38),  # near float32's maximum
                "tiny": lambda: frame_records(rng, 3000, 50, energy_scale=1e-38),
                "never hit": lambda: frame_records(rng, 3000, 50, hit=np.arange(25)),  # elements 25.. never hit
                "one record": lambda: frame_records(rng, 1, 1),
                "no records": lambda: frame_records(rng, 0, 50),
                "no elements": lambda: frame_records(rng, 0, 0),
            }[name]()]
        return frames, kind, split

    def device(self, frames, kind, split):
        return element_sums_cl(frames, kind=kind, split_parity=split)

    def twin(self, frames, kind, split):
        return element_sums_reference(frames, kind=kind, split_parity=split)

    def rule(self, name, want):
        return _close_rule(want)


class TestFrameSumsFluxTwin(KernelTwinTests):
    """The fast path from per-frame element sums to vertex flux (``frame_sums_prefix_step`` and
    ``vertex_window_flux`` in gather.cl, :func:`frame_sums_flux_cl`) against
    :func:`window_flux_reference` of the stacked sums, within 1e-6."""

    # (frames, elements, vertices, output rows, split parity)
    cases = {"one-frame": (1, 40, 30, [0], False), "nine-frames": (9, 150, 110, [3, 4, 5], False),
             "nine-frames-split": (9, 150, 110, [0, 4, 8], True), "no-output-rows": (4, 20, 15, [], False),
             "one-element": (3, 1, 3, [1], True), "unused-vertices": (5, 60, 400, [2], False)}

    def make_inputs(self, rng, case):
        n_rows, n_elements, n_vertices, rows, split = case
        frames = [frame_records(rng, int(rng.integers(0, 1500)), n_elements) for _ in range(n_rows - 1)]
        frames.append(frame_records(rng, 0, n_elements))  # a frame without records
        per_frame = [element_sums_reference([f], kind="indirect", split_parity=split)[0] for f in frames]
        rows = np.array(rows, np.int64)
        back, fwd = random_windows(rng, len(rows), n_elements, rows, n_rows)
        n = rng.integers(1_000, 9_000, n_rows).astype(float)
        return per_frame, n, back, fwd, rows, mesh(rng, n_elements, n_vertices), n_vertices

    def device(self, per_frame, *args):
        return frame_sums_flux_cl(per_frame, *args)

    def twin(self, per_frame, *args):
        return window_flux_reference(np.stack(per_frame), *args)

    def rule(self, name, want):
        return _close_rule(want)


class TestLinearWindowFluxTwin(TestFrameSumsFluxTwin):
    """The same path with ``linear`` (``linear_window`` in gather.cl, docs/05-estimators.md §1.6)
    against the NumPy twin's fit, within 1e-6."""

    def device(self, per_frame, *args):
        return frame_sums_flux_cl(per_frame, *args, linear=True)

    def twin(self, per_frame, *args):
        return window_flux_reference(np.stack(per_frame), *args, linear=True)


def drifting_sums(values, n_emitted, noise_q):
    """(J, E, 1, 3, 4) element sums whose every corner receives n_g * values[g, e] in each channel,
    with Q = noise_q * n_g * values^2 (the photon noise of the linear-window tests)."""
    values = np.asarray(values, float)
    n_emitted = np.asarray(n_emitted, float)
    sums = np.zeros(values.shape + (1, 3, 4))
    sums[..., 0, :, :3] = (n_emitted[:, None] * values)[..., None, None]
    sums[..., 0, :, 3] = (noise_q * n_emitted[:, None] * values ** 2)[..., None]
    return sums


@pytest.mark.parametrize("device", [True, False])
def test_linear_windows_remove_a_drift_and_keep_the_pooled_mean_otherwise(device):
    """Closed forms: lighting a + b g seen through the asymmetric window [f, f + 6] is a + b f from
    the linear fit and a + b (f + 3) (the window's centre) from the pooled mean; a symmetric window
    gives the pooled mean exactly; a slope lost in its photon noise is dropped (lambda = 0)."""
    flux = frame_sums_flux_cl if device else (lambda s, *a, **k: window_flux_reference(np.stack(s), *a, **k))
    n_frames, n = 9, np.array([1000, 2000, 1000, 1500, 1000, 1000, 3000, 1000, 1000.0])
    ev = np.arange(6).reshape(2, 3)
    a, b = 2.0, 0.1
    clean = drifting_sums(np.stack([a + b * np.arange(n_frames)] * 2, axis=1), n, 1e-12)
    ones = np.ones((1, 2), np.uint8)
    f, z = 1, np.zeros((1, 2), np.uint8)
    for linear, want in ((True, a + b * f), (False, None)):
        got = flux(list(clean), n, z, 6 * ones, [f], ev, 6, linear=linear)[0, 0]
        if want is None:
            g = np.arange(f, f + 7)
            want = np.sum(n[g] * (a + b * g)) / n[g].sum()  # the pooled mean: the centre's lighting
            assert want == pytest.approx(a + b * (f + 3), rel=0.02)
        np.testing.assert_allclose(got[:, :3], want, rtol=1e-9)
    # Symmetric windows: x-bar = 0 with equal photons, so the fit is the pooled mean
    even = np.full(n_frames, 1000.0)
    sym = drifting_sums(np.stack([a + b * np.arange(n_frames) ** 2] * 2, axis=1), even, 1e-12)
    np.testing.assert_allclose(flux(list(sym), even, 3 * ones, 3 * ones, [4], ev, 6, linear=True),
                               flux(list(sym), even, 3 * ones, 3 * ones, [4], ev, 6, linear=False), rtol=1e-12)
    # A slope far inside its noise (Q huge) is shrunk away entirely: the pooled mean again
    noisy = drifting_sums(np.stack([a + b * np.arange(n_frames)] * 2, axis=1), n, 1e3)
    np.testing.assert_allclose(flux(list(noisy), n, z, 6 * ones, [f], ev, 6, linear=True)[..., :3],
                               flux(list(noisy), n, z, 6 * ones, [f], ev, 6, linear=False)[..., :3], rtol=1e-12)


def test01_parity_halves_add_up_to_the_whole(rng):
    frames = [frame_records(rng, int(rng.integers(0, 4000)), 300) for _ in range(4)]
    for kind in TestElementSumsTwin.KINDS:
        halves = element_sums_cl(frames, kind=kind, split_parity=True)
        assert halves.shape == (4, 300, 2, 3, 4)
        close(halves.sum(axis=2), element_sums_cl(frames, kind=kind)[:, :, 0])


def test02_elements_never_hit_sum_to_zero(rng):
    never = frame_records(rng, 3000, 50, hit=np.arange(25))  # elements 25.. never hit
    got = element_sums_cl([never], kind="all")
    assert (got[0, 25:] == 0).all() and (got[0, :25] != 0).any()
    assert np.isfinite(element_sums_cl([frame_records(rng, 3000, 50, energy_scale=3e38)], kind="all")).all()


def random_windows(rng, n_out, n_elements, rows, n_rows):
    back = np.minimum(rng.integers(0, 20, (n_out, n_elements)), rows[:, None]).astype(np.uint8)
    fwd = np.minimum(rng.integers(0, 20, (n_out, n_elements)), n_rows - 1 - rows[:, None]).astype(np.uint8)
    return back, fwd


@pytest.mark.parametrize("split", [False, True])
def test03_window_flux_matches_reference(rng, split):
    n_rows, n_elements, n_vertices = 40, 400, 260
    frames = [frame_records(rng, int(rng.integers(0, 3000)), n_elements) for _ in range(n_rows)]
    sums = element_sums_cl(frames, split_parity=split)
    n = rng.integers(10_000, 80_000, n_rows).astype(float)
    rows = np.array([0, 1, 17, 20, 38, 39])
    back, fwd = random_windows(rng, len(rows), n_elements, rows, n_rows)
    ev = mesh(rng, n_elements, n_vertices)
    got = stacked_flux_cl(sums, n, back, fwd, rows, ev, n_vertices)
    want = window_flux_reference(sums, n, back, fwd, rows, ev, n_vertices)
    assert got.shape == (len(rows), 2 if split else 1, n_vertices, 4)
    close(got, want)


def test04_one_frame_window_is_vertex_irradiance(rng):
    n_elements, n_vertices = 500, 300
    ev = mesh(rng, n_elements, n_vertices)
    areas = rng.random(n_vertices) + 0.1
    areas[:5] = 0.0  # vertices of zero area get 0, as in vertex_irradiance
    frames = [frame_records(rng, 6000, n_elements) for _ in range(3)]
    sums = element_sums_cl(frames, kind="indirect")
    n = np.array([40_000.0, 41_000.0, 39_000.0])
    zero = np.zeros((1, n_elements), np.uint8)
    flux = stacked_flux_cl(sums, n, zero, zero, [1], ev, n_vertices)
    got = irradiance(flux[0, 0], areas)
    r = frames[1]
    ind = ~r.direct
    want = vertex_irradiance(r.element[ind], r.b1[ind], r.b2[ind], r.energy[ind], ev, areas, n[1])
    close(got, want)


def test05_window_pools_photons_of_all_its_frames(rng):
    # A window over three frames equals vertex_irradiance of their records pooled, over sum N
    n_elements, n_vertices = 200, 150
    ev = mesh(rng, n_elements, n_vertices)
    areas = rng.random(n_vertices) + 0.5
    frames = [frame_records(rng, 2000, n_elements) for _ in range(3)]
    n = np.array([10_000.0, 20_000.0, 40_000.0])
    sums = element_sums_cl(frames, kind="all")
    one = np.ones((1, n_elements), np.uint8)
    got = irradiance(stacked_flux_cl(sums, n, one, one, [1], ev, n_vertices)[0, 0], areas)
    cat = lambda name: np.concatenate([getattr(r, name) for r in frames])  # noqa: E731
    want = vertex_irradiance(cat("element"), cat("b1"), cat("b2"), cat("energy"), ev, areas, n.sum())
    close(got, want)


def test06_parity_halves_estimate_the_whole(rng):
    n_elements, n_vertices = 300, 200
    frames = [frame_records(rng, 4000, n_elements) for _ in range(5)]
    ev = mesh(rng, n_elements, n_vertices)
    n = np.full(5, 30_000.0)
    back = np.full((1, n_elements), 2, np.uint8)
    halves = stacked_flux_cl(element_sums_cl(frames, split_parity=True), n, back, back, [2], ev, n_vertices)
    whole = stacked_flux_cl(element_sums_cl(frames), n, back, back, [2], ev, n_vertices)
    # Each half is normalised by half the photons: their mean is the full map
    close(halves[0, :, :, :3].mean(axis=0), whole[0, 0, :, :3])


def test07_bitwise_repeatable(rng):
    n_elements, n_vertices = 2000, 1200
    frames = [frame_records(rng, 20_000, n_elements) for _ in range(10)]
    ev = mesh(rng, n_elements, n_vertices)
    n = np.full(10, 2e4)
    rows = np.arange(2, 8)
    back, fwd = random_windows(rng, len(rows), n_elements, rows, 10)
    first_sums = element_sums_cl(frames, split_parity=True)
    first = stacked_flux_cl(first_sums, n, back, fwd, rows, ev, n_vertices)
    for _ in range(2):
        sums = element_sums_cl(frames, split_parity=True)
        assert sums.tobytes() == first_sums.tobytes()
        assert stacked_flux_cl(sums, n, back, fwd, rows, ev, n_vertices).tobytes() == first.tobytes()


def test08_refuses_windows_outside_the_table(rng):
    frames = [frame_records(rng, 100, 10) for _ in range(3)]
    sums = element_sums_cl(frames)
    ev = mesh(rng, 10, 8)
    two = np.full((1, 10), 2, np.uint8)
    with pytest.raises(ValueError, match="outside"):
        stacked_flux_cl(sums, np.ones(3), two, two, [1], ev, 8)
    with pytest.raises(ValueError, match="outside"):
        window_flux_reference(sums, np.ones(3), two, two, [1], ev, 8)
    with pytest.raises(ValueError, match="kind"):
        element_sums_cl(frames, kind="sometimes")


@pytest.mark.parametrize("split", [False, True])
def test_gather_from_frame_sums_gives_the_same_bits(rng, split):
    """Sums made one frame at a time (and kept, pipeline/collection/maps.py) are the bits of the frames
    summed in one call, give the same flux, and agree with the NumPy twin."""
    n_elements, n_vertices = 150, 110
    frames = [frame_records(rng, int(rng.integers(0, 1500)), n_elements) for _ in range(8)]
    frames.append(frame_records(rng, 0, n_elements))
    ev = mesh(rng, n_elements, n_vertices)
    rows = np.array([3, 4, 5])
    back, fwd = random_windows(rng, 3, n_elements, rows, len(frames))
    n = rng.integers(1_000, 9_000, len(frames)).astype(float)
    per_frame = [element_sums_cl([f], kind="indirect", split_parity=split)[0] for f in frames]
    got = frame_sums_flux_cl(per_frame, n, back, fwd, rows, ev, n_vertices)
    together = element_sums_cl(frames, kind="indirect", split_parity=split)
    assert np.stack(per_frame).tobytes() == together.tobytes()
    assert got.tobytes() == stacked_flux_cl(together, n, back, fwd, rows, ev, n_vertices).tobytes()
    close(got, window_flux_reference(np.stack(per_frame), n, back, fwd, rows, ev, n_vertices))
    with pytest.raises(ValueError, match="frame sums"):
        frame_sums_flux_cl(per_frame[:2] + [per_frame[2][:10]], n[:3], back[:, :], fwd, [1, 1, 1], ev, n_vertices)
