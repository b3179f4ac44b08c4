"""Light does not depend on how big the rest of the scene is (docs/14-robustness.md §5; pipeline/photons/raycast.py).

Ray offsets follow each hit triangle's own float precision. A cornell box inside a black backdrop
cube of side 10 .. 1e6 must get the same light as the box alone: the backdrop absorbs whatever
leaves the box, so physics says the box's deposits do not change, and only a scene-scaled offset
could change them. The noise floor is the standard error over K = 8 independent photon batches
(stated in each assertion); the test also asserts that error bar is tight (< 3 % of the value).
A closed furnace box far from the origin checks the large offsets a large coordinate needs.
"""
from __future__ import annotations

import numpy as np
import pytest

from pipeline.config import PhotonConfig
from pipeline.photons.tracing import PhotonRange, trace_batch
from pipeline.scene import ElementMesh, read_scene
from pipeline.scene.builtin import cornell, shapes
from pipeline.scene.builtin.gltf_builder import GltfBuilder
from pipeline.store import DIRECT_BIT, ELEMENT_MASK

K = 8
N = 20_000


def _box_light(tmp_path, backdrop: float | None):
    """(direct, indirect) flux per photon deposited on the cornell box's own elements, per batch."""
    b = cornell.build()
    if backdrop is not None:
        black = b.add_material("backdrop", (0.0, 0.0, 0.0))
        b.add_node("backdrop", b.add_mesh("backdrop", *shapes.box((backdrop,) * 3, (0.5, 0.5, 0.5), inward=True),
                                          material=black))
    # Elements coarse enough for the backdrop (the box's sums are per instance, whatever the size)
    b.set_scene_extras({"photonloom": {"element_size": max(2.0, (backdrop or 0) / 20), "frames": 1}})
    scene = read_scene(b.write(tmp_path / f"cornell_{backdrop}.glb"))
    elements = ElementMesh.build(scene)
    state = scene.pose_frame(1)
    box_instances = [i for i, inst in enumerate(scene.instances) if not inst.name.startswith("backdrop")]
    out = []
    for k in range(K):
        batch = trace_batch(state, elements, PhotonRange(1, k * N, N), PhotonConfig(seed=3, photon_depth=50))
        elem = (batch.key & ELEMENT_MASK).astype(np.int64)
        tri = np.searchsorted(elements.triangle_offset, elem, side="right") - 1
        on_box = np.isin(state.triangle_instance[tri], box_instances)
        direct = (batch.key & DIRECT_BIT) > 0
        e = batch.energy.astype(np.float64).sum(axis=1)
        out.append((e[on_box & direct].sum() / N, e[on_box & ~direct].sum() / N))
    return np.array(out)


def _agree(a, b, what):
    """Means of two K-batch samples within 3 combined standard errors, each error under 3 %."""
    ma, mb = a.mean(), b.mean()
    sa, sb = a.std(ddof=1) / np.sqrt(len(a)), b.std(ddof=1) / np.sqrt(len(b))
    noise = np.hypot(sa, sb)
    assert abs(ma - mb) <= 3 * noise, f"{what}: {ma:.5g} vs {mb:.5g}, noise (1 SE) {noise:.3g}"
    assert sa < 0.03 * ma and sb < 0.03 * mb, f"{what}: noise too large to tell ({sa:.3g}, {sb:.3g})"


@pytest.fixture(scope="module")
def alone(tmp_path_factory):
    return _box_light(tmp_path_factory.mktemp("alone"), None)


@pytest.mark.parametrize("size", [10.0, 1e2, 1e3, 1e4, 1e5, 1e6])
def test_box_light_is_unchanged_by_a_backdrop_of_any_size(tmp_path, alone, size):
    inside = _box_light(tmp_path, size)
    _agree(inside[:, 0], alone[:, 0], f"direct, backdrop {size:g}")
    _agree(inside[:, 1], alone[:, 1], f"indirect, backdrop {size:g}")


@pytest.mark.parametrize("distance", [0.0, 1e2, 1e3, 1e4])
def test_furnace_far_from_the_origin(tmp_path, distance):
    """A closed, tilted unit box of albedo rho at (distance, 0, 0): indirect = Phi rho / (1 - rho) (closed form)."""
    rho, intensity = 0.5, 3.0
    b = GltfBuilder()
    grey = b.add_material("grey", (rho, rho, rho))
    # Tilted, so that its walls are not axis-aligned planes float32 holds exactly
    b.add_node("box", b.add_mesh("box", *shapes.box((1.0, 1.0, 1.0), inward=True), material=grey),
               translation=(distance, 0.0, 0.0), rotation=shapes.axis_angle((1, 2, 3), 0.7))
    b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), intensity), translation=(distance + 0.1, 0.2, 0.05))
    b.set_scene_extras({"photonloom": {"element_size": 2.0, "frames": 1}})
    scene = read_scene(b.write(tmp_path / "furnace.glb"))
    elements, state = ElementMesh.build(scene), scene.pose_frame(1)
    phi = 4 * np.pi * intensity
    indirect = []
    for k in range(K):
        batch = trace_batch(state, elements, PhotonRange(1, k * N, N), PhotonConfig(seed=5, photon_depth=200))
        direct = (batch.key & DIRECT_BIT) > 0
        assert np.isclose(batch.energy[direct, 0].astype(np.float64).sum() / N, phi, rtol=1e-5)
        indirect.append(batch.energy[~direct, 0].astype(np.float64).sum() / N)
    indirect = np.array(indirect)
    se = indirect.std(ddof=1) / np.sqrt(K)
    expected = phi * rho / (1 - rho)
    assert abs(indirect.mean() - expected) <= 3 * se, (indirect.mean(), expected, se)
    assert se < 0.03 * expected
