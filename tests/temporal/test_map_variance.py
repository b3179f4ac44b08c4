"""The variance ``illumination_maps(with_variance=True)`` reports (docs/05-estimators.md §1.3) is the
spread two independent photon sets really show, on real stores: what the coordinator's F_max check
(pipeline/segments.growth_ratio) weighs bias against."""
from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from pipeline.cli import main
from pipeline.config import RenderConfig
from pipeline.scene import ElementMesh, Scene
from pipeline.scene.builtin import write_builtin
from pipeline.store import PhotonStore
from pipeline.temporal import illumination_maps
from pipeline.tonemap import luminance

FRAMES = (60, 67)


@pytest.fixture(scope="module")
def stores(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("variance")
    scene = write_builtin("room", tmp / "room.glb")
    out = []
    for seed in (0, 1):
        o = tmp / f"seed{seed}"
        result = CliRunner().invoke(main, [
            "render", str(scene), "--frames", f"{FRAMES[0]}-{FRAMES[1]}", "--out", str(o), "--resolution", "16x12",
            "--spp", "1", "--photons", "20000", "--scheduler", "synchronous", "--quiet", "--temporal", "off",
            "--seed", str(seed)])
        assert result.exit_code == 0, result.output
        out.append(PhotonStore.open(str(o / "photons.zarr")))
    sc = Scene.load(scene)
    return sc, ElementMesh.build(sc), out


# Fixed windows: both seeds pool the same frames. Adaptive windows are chosen from each seed's own
# counts, so two seeds also differ by where their windows end (1.18 here), which is not photon noise.
@pytest.mark.parametrize("mode, fmax", [("off", 0), ("fixed", 6)])
def test_the_reported_variance_is_the_spread_between_seeds(stores, mode, fmax):
    scene, elements, (a, b) = stores
    frames = [f - 1 for f in range(FRAMES[0], FRAMES[1] + 1)]
    lits = [list(illumination_maps(s, elements, scene, frames, mode=mode, fmax=fmax, config=RenderConfig(),
                                   with_variance=True)) for s in (a, b)]
    seen = expected = 0.0
    for la, lb in zip(*lits):
        areas = elements.vertex_areas(scene.pose_frame(la.frame_index + 1))
        d = luminance(la.irradiance) - luminance(lb.irradiance)
        seen += float(np.sum(areas * d * d))
        expected += float(np.sum(areas * (la.variance + lb.variance)))
    # E[(y_a - y_b)^2] = var_a + var_b; 8 frames of ~1,900 vertices: the sum's own spread is ~3 %
    assert seen / expected == pytest.approx(1.0, abs=0.12)


def test_variance_is_only_of_the_unfiltered_full_map(stores):
    scene, elements, (a, _) = stores
    for kw in ({"spatial_filter": True}, {"split_parity": True}):
        with pytest.raises(ValueError, match="with_variance"):
            next(illumination_maps(a, elements, scene, [FRAMES[0] - 1], mode="off", fmax=0, with_variance=True, **kw))
