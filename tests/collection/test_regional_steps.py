"""The regional step test (pipeline/collection/regional_steps.py) on count tables with known answers: a
step of a known size at a known boundary in one region is found there and nowhere else, no
window crosses it, a drift never is, and the windows of a chunk do not depend on the rows around
it."""
from __future__ import annotations

import numpy as np
import pytest

from pipeline.collection.maps import WindowSpec, collection_windows
from pipeline.collection.regional_steps import clamp_windows, element_regions, step_boundaries
from pipeline.config import CollectionConfig, PhotonConfig
from pipeline.scene import read_scene

RATE = 30.0  # hits an element a frame: Condition (1) alone cannot see a 40 % change at this count


def _table(steps=((12, 0, 1.4),), frames=24, per_region=50, regions=4, drift=0.0, seed=0, rate=RATE):
    """Poisson counts of ``regions`` x ``per_region`` elements; each (frame, region, factor) of
    ``steps`` scales the region's rate from that frame on; ``drift`` is a rate change a frame."""
    rng = np.random.default_rng(seed)
    lam = np.full((frames, regions * per_region), float(rate))
    lam *= (1.0 + drift * np.arange(frames))[:, None]
    for frame, region, factor in steps:
        lam[frame:, region * per_region:(region + 1) * per_region] *= factor
    return rng.poisson(lam).astype(np.uint32), np.repeat(np.arange(regions), per_region)


def test_a_step_is_found_at_its_boundary_in_its_region_only():
    counts, regions = _table()
    cut = step_boundaries(counts, np.full(len(counts), 1e4), regions, 6.0)
    assert np.argwhere(cut).tolist() == [[11, 0]]  # boundary 11 | 12 of region 0


def test_photon_budgets_are_normalised():
    counts, regions = _table(steps=())
    n = np.full(len(counts), 1e4)
    counts[10:] *= 2  # twice the photons from frame 10 on: the same rate, no step
    n[10:] *= 2
    assert not step_boundaries(counts, n, regions, 6.0).any()


def test_a_slow_drift_is_not_a_step():
    counts, regions = _table(steps=(), drift=0.02, frames=40)  # +80 % over the table, 2 % a frame
    assert not step_boundaries(counts, np.full(len(counts), 1e4), regions, 6.0).any()


def test_a_small_real_change_is_not_a_step():
    # 5 % at 40,000 hits a region and frame is 7 sigma of the difference: real, but not a jump
    counts, regions = _table(steps=((12, 0, 1.05),), rate=800)
    n = np.full(len(counts), 1e4)
    assert step_boundaries(counts, n, regions, 4.0)[11, 0]
    assert not step_boundaries(counts, n, regions, 4.0, relative=0.1).any()
    assert step_boundaries(counts, n, regions, 4.0, relative=0.04)[11, 0]


def test_no_window_crosses_a_step_and_others_are_untouched():
    counts, regions = _table()
    cut = step_boundaries(counts, np.full(len(counts), 1e4), regions, 6.0)
    rows = np.arange(len(counts))
    back = np.full((len(rows), len(regions)), 7, np.uint8)
    b, w = clamp_windows(back, back.copy(), rows, cut[:, regions])
    first = rows[:, None] - b.astype(int)
    last = rows[:, None] + w.astype(int)
    in_step = regions == 0
    crosses = (first <= 11) & (last >= 12)
    assert not crosses[:, in_step].any()
    # elsewhere only the table's own ends stop a window
    assert (b[:, ~in_step] == np.minimum(7, rows)[:, None]).all()
    assert (w[:, ~in_step] == np.minimum(7, len(rows) - 1 - rows)[:, None]).all()
    assert b[12, 0] == 0 and w[11, 0] == 0 and b[13, 0] == 1 and w[10, 0] == 1


def test_windows_stop_at_a_jump_condition_1_alone_misses():
    counts, regions = _table(frames=30, steps=((15, 1, 1.4),))
    emitted = np.full(len(counts), 1e4)
    levels = [regions]
    frames = np.arange(4, 26)
    paper = collection_windows(counts, emitted, frames, WindowSpec("adaptive", 14), CollectionConfig(step_levels=0))
    ours = collection_windows(counts, emitted, frames, WindowSpec("adaptive", 14),
                              CollectionConfig(step_levels=1, step_relative=0.01), regions=levels)
    elements = regions == 1

    def crossing(back, fwd):
        return ((frames[:, None] - back.astype(int) <= 14) & (frames[:, None] + fwd.astype(int) >= 15))[:, elements]

    assert crossing(*paper).mean() > 0.2  # per element the 40 % jump hides in the noise
    assert not crossing(*ours).any()
    assert (ours[0][:, ~elements] == paper[0][:, ~elements]).all()


def test_a_chunks_windows_do_not_depend_on_the_rows_around_it():
    counts, regions = _table(frames=40, steps=((20, 2, 0.6), (9, 0, 1.5)))
    emitted = np.full(len(counts), 1e4)
    config = CollectionConfig(step_levels=1, step_relative=0.01)
    whole = collection_windows(counts, emitted, np.arange(40), WindowSpec("adaptive", 14), config,
                               regions=[regions])
    for lo in (0, 13, 26):
        frames = np.arange(lo, min(lo + 13, 40))
        first = max(0, lo - 8)
        part = collection_windows(counts[first:], emitted, frames, WindowSpec("adaptive", 14), config,
                                  regions=[regions], counts_from=first)
        assert (part[0] == whole[0][frames]).all() and (part[1] == whole[1][frames]).all()


def test_regions_follow_instances_and_cells():
    vertex_local = np.array([[0.1, 0.1, 0], [0.2, 0.1, 0], [0.1, 0.2, 0], [1.5, 0.1, 0], [1.6, 0.1, 0],
                             [1.5, 0.2, 0]])
    elements = np.array([[0, 1, 2], [3, 4, 5], [0, 1, 2]])
    instance = np.array([0, 0, 1])
    r = element_regions(elements, vertex_local, instance, 1.0)
    assert len(set(r.tolist())) == 3  # another cell, another instance
    assert element_regions(elements[:2], vertex_local, instance[:2], 4.0).tolist() == [0, 0]
    with pytest.raises(ValueError):
        element_regions(elements, vertex_local, instance, 0.0)


def test_levels_need_regions():
    counts, _ = _table(steps=())
    with pytest.raises(ValueError):
        collection_windows(counts, np.full(len(counts), 1e4), [5], WindowSpec("adaptive", 8),
                           CollectionConfig(step_levels=2))


@pytest.fixture(scope="module")
def room_jump(tmp_path_factory):
    """ROOM frames 63-79 at 20,000 photons a frame, with and without the error benchmark's light
    jump at frame 71 (pipeline/benchmarks/error.py): real photons in a real store."""
    from pipeline.benchmarks.error import write_scene
    from pipeline.run.shoot import plan, shoot
    from pipeline.scene import ElementMesh
    from pipeline.store import PhotonStore

    root = tmp_path_factory.mktemp("room-jump")
    out = {}
    for name, event in (("jump", 71), ("steady", 500)):  # 500: after the last frame, no jump
        path = write_scene("room", root / f"{name}.glb", event)
        scene = read_scene(path)
        shoot(plan(scene, "63-79", 20_000, PhotonConfig()), str(root / f"{name}.zarr"), scheduler="synchronous",
              progress=False)
        out[name] = (ElementMesh.build(scene), PhotonStore.open(str(root / f"{name}.zarr")))
    return out


def _windows_around_the_jump(mesh, store, levels):
    from pipeline.collection.maps import step_regions

    config = CollectionConfig(step_levels=levels)
    frames = np.arange(64, 79)
    counts = store.counts(kind="all")
    back, fwd = collection_windows(counts, store.emitted(None).astype(float), frames - 1, WindowSpec("adaptive", 14),
                                   config, regions=step_regions(mesh, config))
    hit = counts.sum(axis=0) > 0
    crosses = (frames[:, None] - back.astype(int) <= 70) & (frames[:, None] + fwd.astype(int) >= 71)
    return back, fwd, crosses[np.isin(frames, (70, 71))][:, hit].mean()


def test_room_windows_stop_at_a_light_jump(room_jump):
    mesh, store = room_jump["jump"]
    *_, paper = _windows_around_the_jump(mesh, store, 0)
    *_, ours = _windows_around_the_jump(mesh, store, 4)
    # measured: 0.96 of the lit elements pool across the jump with Condition (1) alone, 0.23 with steps
    assert paper > 0.8 and ours < 0.3


def test_room_without_a_jump_keeps_the_papers_windows(room_jump):
    mesh, store = room_jump["steady"]
    b0, w0, _ = _windows_around_the_jump(mesh, store, 0)
    b4, w4, _ = _windows_around_the_jump(mesh, store, 4)
    assert (b0 == b4).all() and (w0 == w4).all()
