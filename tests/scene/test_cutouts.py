"""Alpha-masked surfaces (pipeline/scene/cutouts.py): rays pass a MASK surface's holes, camera,
shadow and photon rays alike; an element's area counts its solid part only, so a leaf-like
surface with holes finer than its elements has the irradiance of its solid texels, a point
light's I cos / r^2; a blended sheet of alpha a stops a of the rays and photons reaching it, its
irradiance still I cos / r^2, each ray's decision its own hash; a bad alpha mode is a one-line error."""
from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner
from pygltflib import GLTF2

from kernels.record_layout import DIRECT_BIT, ELEMENT_MASK
from pipeline.cli import main
from pipeline.collection.estimators import vertex_irradiance
from pipeline.config import PhotonConfig
from pipeline.errors import SceneError
from pipeline.frames.images import frame_paths, read_exr
from pipeline.photons.raycast import RayCaster
from pipeline.photons.tracing import PhotonRange, trace_batch
from pipeline.scene import ElementMesh, read_scene
from pipeline.scene.builtin.gltf_builder import GltfBuilder
from pipeline.scene.cutouts import ray_uniforms
from tests.conftest import QUAD, QUAD_FACES, basic_builder

LAMP_AT = np.array([1.0, 2.0, 1.0])  # basic_builder's lamp, 10 W/sr white
SHEET_Y = 1.0


def sheet(path, alpha: np.ndarray, *, mode="MASK", cutoff=0.5, element_size=None, extra=None):
    """basic_builder's floor and lamp with a 2 x 2 sheet at y = 1 between them (u = x / 2, v = z / 2),
    its base-colour texture white with the given alpha (H, W) in [0, 255]."""
    b = basic_builder()
    rgba = np.concatenate([np.full(alpha.shape + (3,), 255, np.uint8), alpha[..., None].astype(np.uint8)], axis=2)
    tex = b.add_texture(rgba, mag_filter=9728)  # NEAREST: the holes' edges where the texels put them
    mat = b.add_material("leaf", (0.5, 0.5, 0.5), base_color_texture=tex, alpha_mode=mode, alpha_cutoff=cutoff)
    uv = np.c_[QUAD[:, 0] / 2, QUAD[:, 2] / 2]
    b.add_node("sheet", b.add_mesh("sheet", QUAD, QUAD_FACES, material=mat, texcoords={0: uv}),
               translation=(0, SHEET_Y, 0))
    if element_size:
        b.set_scene_extras({"photonloom": {"element_size": element_size}})
    if extra:
        extra(b)
    return b.write(path)


def _half(width=8):
    alpha = np.full((width, width), 255)
    alpha[:, : width // 2] = 0  # u < 0.5 (x < 1) is a hole
    return alpha


def test_rays_pass_the_holes_and_stop_on_the_solid_part(tmp_path):
    state = read_scene(sheet(tmp_path / "half.glb", _half())).pose(0)
    caster = RayCaster(state)
    down = np.tile([0.0, -1.0, 0.0], (2, 1)).astype(np.float32)
    origins = np.array([[0.5, 3, 1], [1.5, 3, 1]], np.float32)  # over the hole, over the solid half
    tri, _, _, t = caster.intersect(origins, down)
    assert state.triangle_instance[tri].tolist() == [0, 1]  # the floor through the hole, then the sheet
    np.testing.assert_allclose(t, [3.0, 2.0], rtol=1e-5)
    floor = np.array([[0.5, 0, 1], [1.5, 0, 1]], np.float32)
    up = -down
    assert caster.occluded(floor + up * 1e-3, up, np.full(2, 5.0, np.float32)).tolist() == [False, True]


@pytest.mark.parametrize("mode, cutoff, hit", [("MASK", 0.5, 0), ("MASK", 0.0, 1), ("BLEND", 0.5, 0),
                                               ("OPAQUE", 0.5, 1)])
def test_the_cutoff_and_the_modes(tmp_path, mode, cutoff, hit):
    state = read_scene(sheet(tmp_path / "m.glb", _half(), mode=mode, cutoff=cutoff)).pose(0)
    tri, *_ = RayCaster(state).intersect(np.array([[0.5, 3, 1]], np.float32), np.array([[0, -1, 0]], np.float32))
    assert state.triangle_instance[tri[0]] == hit


def test_the_lamp_lights_the_floor_through_the_hole_only(tmp_path):
    scene = read_scene(sheet(tmp_path / "half.glb", _half()))
    elements = ElementMesh.build(scene)
    batch = trace_batch(scene.pose(0), elements, PhotonRange(1, 0, 40_000), PhotonConfig())
    direct = (batch.key & DIRECT_BIT) != 0
    element = batch.key & ELEMENT_MASK
    on_floor = direct & (elements.element_instance[element] == 0)
    centre = elements.element_positions(scene.pose(0)).mean(axis=1)[element[on_floor]]
    under = np.abs(centre[:, 2] - 1) < 0.5
    x = centre[under, 0]
    assert (x < 0.9).sum() > 100 and (x > 1.1).sum() == 0  # light below the hole, a shadow below the rest


def test_a_sheet_with_fine_holes_has_the_irradiance_of_its_solid_texels(tmp_path):
    # A 1-texel checker of holes (64 x 64 over 2 m: 3 cm), elements ~0.2 m: each element about half
    # solid. The sheet's direct irradiance from the lamp above is I cos / r^2 on its solid texels
    checker = (np.indices((64, 64)).sum(axis=0) % 2) * 255
    scene = read_scene(sheet(tmp_path / "checker.glb", checker, element_size=0.2))
    elements = ElementMesh.build(scene)
    sheet_elements = elements.element_instance == 1
    assert 0.4 < elements.coverage[sheet_elements].mean() < 0.6
    state = scene.pose(0)
    batch = trace_batch(state, elements, PhotonRange(1, 0, 400_000), PhotonConfig())
    direct = (batch.key & DIRECT_BIT) != 0
    e = vertex_irradiance(batch.key[direct] & ELEMENT_MASK, batch.bary[direct, 0], batch.bary[direct, 1],
                          batch.energy[direct], elements, elements.vertex_areas(state), batch.photons_emitted)
    pos = elements.vertex_positions(state)
    d = LAMP_AT - pos
    r2 = np.einsum("ij,ij->i", d, d)
    closed = 10.0 * (d[:, 1] / np.sqrt(r2)) / r2  # I cos / r^2 on the sheet's upward face
    inner = (elements.vertex_instance == 1) & (np.abs(pos[:, 0] - 1) < 0.5) & (np.abs(pos[:, 2] - 1) < 0.5)
    ratio = e[inner, 0] / closed[inner]
    assert abs(np.median(ratio) - 1) < 0.05  # diluted by the holes it would be 0.5


def test_a_bad_alpha_mode_is_a_one_line_error(tmp_path):
    with pytest.raises(SceneError, match=r"materials\[1\].alphaMode: 'CUTOUT' is not one of OPAQUE, MASK, BLEND"):
        read_scene(sheet(tmp_path / "bad.glb", _half(), mode="CUTOUT"))


def test_an_animated_cutoff_moves_the_holes(tmp_path):
    # The sheet's half-transparent texels (alpha 128) are holes while the cut-off is 0.6 and solid
    # once it falls to 0.4 (KHR_animation_pointer, STEP at 0.5 s); the frames' state keys differ
    alpha = np.full((8, 8), 255)
    alpha[:, :4] = 128
    scene = read_scene(sheet(tmp_path / "fade.glb", alpha, cutoff=0.6, extra=lambda b: b.add_pointer_animation(
        "fade", "/materials/1/alphaCutoff", [0, 0.5], [0.6, 0.4], "STEP")))
    origin, down = np.array([[0.5, 3, 1]], np.float32), np.array([[0, -1, 0]], np.float32)
    reached_floor = []
    for t in (0.0, 0.75):
        state = scene.pose(t)
        tri, *_ = RayCaster(state).intersect(origin, down)
        reached_floor.append(state.triangle_instance[tri[0]] == 0)
    assert reached_floor == [True, False] and scene.pose(0).state_key != scene.pose(0.75).state_key


BLEND_ALPHA = 0.3


def test_a_blended_pane_stops_alpha_of_the_rays(tmp_path):
    # a pane of alpha 77/255 over the floor: parallel rays down, shadow rays up
    scene = read_scene(sheet(tmp_path / "pane.glb", np.full((4, 4), round(255 * BLEND_ALPHA)), mode="BLEND"))
    state = scene.pose(0)
    caster = RayCaster(state)
    rng = np.random.default_rng(5)
    n = 100_000
    origins = np.c_[rng.uniform(0.2, 1.8, n), np.full(n, 3.0), rng.uniform(0.2, 1.8, n)].astype(np.float32)
    down = np.tile([0.0, -1.0, 0.0], (n, 1)).astype(np.float32)
    tri, *_ = caster.intersect(origins, down)
    stopped = (state.triangle_instance[tri] == 1).mean()
    alpha = round(255 * BLEND_ALPHA) / 255
    assert abs(stopped - alpha) < 4 * np.sqrt(alpha * (1 - alpha) / n)  # binomial, 4 sigma
    up = -down
    floor = origins.copy()
    floor[:, 1] = 1e-3
    shadowed = caster.occluded(floor, up, np.full(n, 5.0, np.float32)).mean()
    assert abs(shadowed - alpha) < 4 * np.sqrt(alpha * (1 - alpha) / n)
    again, *_ = caster.intersect(origins, down)
    np.testing.assert_array_equal(again, tri)  # the same rays decide alike


def test_a_blended_pane_has_the_irradiance_of_the_light_on_it_and_passes_the_rest(tmp_path):
    alpha = round(255 * BLEND_ALPHA) / 255
    counts = []
    for mode in (None, "BLEND"):  # the bare floor, then under the pane
        if mode is None:
            path = basic_builder().write(tmp_path / "bare.glb")
        else:
            path = sheet(tmp_path / "pane.glb", np.full((4, 4), round(255 * BLEND_ALPHA)), mode="BLEND",
                         element_size=0.2)
        scene = read_scene(path)
        elements = ElementMesh.build(scene)
        state = scene.pose(0)
        batch = trace_batch(state, elements, PhotonRange(1, 0, 200_000), PhotonConfig())
        direct = (batch.key & DIRECT_BIT) != 0
        element = batch.key[direct] & ELEMENT_MASK
        centre = elements.element_positions(state).mean(axis=1)[element]
        under = (elements.element_instance[element] == 0) & (np.abs(centre[:, 0] - 1) < 0.8) \
            & (np.abs(centre[:, 2] - 1) < 0.8)
        counts.append(under.sum())
        if mode is not None:
            pane = elements.element_instance == 1
            np.testing.assert_allclose(elements.coverage[pane], alpha, rtol=1e-6)
            e = vertex_irradiance(element, batch.bary[direct, 0], batch.bary[direct, 1], batch.energy[direct],
                                  elements, elements.vertex_areas(state), batch.photons_emitted)
            pos = elements.vertex_positions(state)
            d = LAMP_AT - pos
            r2 = np.einsum("ij,ij->i", d, d)
            closed = 10.0 * (d[:, 1] / np.sqrt(r2)) / r2
            inner = (elements.vertex_instance == 1) & (np.abs(pos[:, 0] - 1) < 0.5) & (np.abs(pos[:, 2] - 1) < 0.5)
            assert abs(np.median(e[inner, 0] / closed[inner]) - 1) < 0.05  # not alpha x it
    passed = counts[1] / counts[0]
    assert abs(passed - (1 - alpha)) < 0.03, passed  # the floor under the pane gets 1 - alpha of the light


def test_ray_uniforms_are_uniform_and_depend_on_every_word():
    rng = np.random.default_rng(2)
    n = 200_000
    origins = rng.normal(size=(n, 3)).astype(np.float32)
    dirs = rng.normal(size=(n, 3)).astype(np.float32)
    tri = rng.integers(0, 1000, n)
    xi = ray_uniforms(origins, dirs, tri)
    assert (xi >= 0).all() and (xi < 1).all()
    counts = np.histogram(xi, bins=10, range=(0, 1))[0]
    assert np.abs(counts / n - 0.1).max() < 0.005
    np.testing.assert_array_equal(ray_uniforms(origins, dirs, tri), xi)
    nudged = origins.copy()
    nudged[:, 2] = np.nextafter(nudged[:, 2], np.float32(np.inf))  # one ulp of one coordinate
    assert abs(np.corrcoef(ray_uniforms(nudged, dirs, tri), xi)[0, 1]) < 0.01
    assert abs(np.corrcoef(ray_uniforms(origins, dirs, tri + 1), xi)[0, 1]) < 0.01


def _glass(path, *, transmission=1.0, ior=1.5, roughness=0.0, texture=None, **kw):
    """basic_builder's floor and lamp with a 2 x 2 pane of thin glass at y = 1 between them."""
    b = basic_builder()
    mat = b.add_material("glass", (1.0, 1.0, 1.0), roughness=roughness)
    ext = {"transmissionFactor": transmission}
    if texture is not None:
        ext["transmissionTexture"] = {"index": b.add_texture(texture)}
    b.gltf.materials[mat].extensions["KHR_materials_transmission"] = ext
    b.gltf.materials[mat].extensions["KHR_materials_ior"] = {"ior": ior}
    b._use_extension("KHR_materials_transmission")
    b._use_extension("KHR_materials_ior")
    uv = np.c_[QUAD[:, 0] / 2, QUAD[:, 2] / 2]
    b.add_node("pane", b.add_mesh("pane", QUAD, QUAD_FACES, material=mat, texcoords={0: uv}),
               translation=(0, SHEET_Y, 0))
    if kw.get("element_size"):
        b.set_scene_extras({"photonloom": {"element_size": kw["element_size"]}})
    return b.write(path)


def _stopped(state, caster, cos_theta: float, n: int = 100_000) -> float:
    """Share of n parallel rays at cos_theta to the pane's normal that stop on it (the pane is instance 1)."""
    rng = np.random.default_rng(9)
    sin = np.sqrt(1 - cos_theta**2)
    d = np.tile([sin, -cos_theta, 0.0], (n, 1)).astype(np.float32)
    hit_at = np.c_[rng.uniform(0.3, 1.7, n), np.full(n, SHEET_Y), rng.uniform(0.3, 1.7, n)]
    origins = (hit_at - 2.0 * d).astype(np.float32)
    tri, *_ = caster.intersect(origins, d)
    return float(((tri >= 0) & (state.triangle_instance[tri] == 1)).mean())  # those passing may miss the floor


@pytest.mark.parametrize("ior, cos_theta", [(1.5, 1.0), (1.5, 0.5), (1.5, 0.2), (2.4, 1.0)])
def test_clear_glass_reflects_schlicks_share(tmp_path, ior, cos_theta):
    state = read_scene(_glass(tmp_path / "glass.glb", ior=ior)).pose(0)
    f0 = ((ior - 1) / (ior + 1)) ** 2
    fresnel = f0 + (1 - f0) * (1 - cos_theta) ** 5
    n = 100_000
    assert abs(_stopped(state, RayCaster(state), cos_theta, n) - fresnel) < 4 * np.sqrt(fresnel * (1 - fresnel) / n)


def test_glass_is_a_mirror_where_it_stops_and_its_elements_record_nothing(tmp_path):
    scene = read_scene(_glass(tmp_path / "glass.glb"))
    assert scene.materials[1].kind == "mirror" and scene.materials[1].transmission == 1.0
    assert read_scene(_glass(tmp_path / "frosted.glb", roughness=0.8)).materials[1].kind == "diffuse"
    elements = ElementMesh.build(scene)
    state = scene.pose(0)
    batch = trace_batch(state, elements, PhotonRange(1, 0, 100_000), PhotonConfig())
    element = batch.key & ELEMENT_MASK
    assert not (elements.element_instance[element] == 1).any()  # a mirror records nothing
    bare = read_scene(basic_builder().write(tmp_path / "bare.glb"))
    bare_batch = trace_batch(bare.pose(0), ElementMesh.build(bare), PhotonRange(1, 0, 100_000), PhotonConfig())
    direct = [((b.key & DIRECT_BIT) != 0).sum() for b in (batch, bare_batch)]
    # photons pass the pane as light's first hit still: about 1 - F of the floor's direct photons
    # under the pane's shadow region (the pane covers the floor's centre seen from the lamp)
    assert 0.85 < direct[0] / direct[1] < 0.99


def test_a_transmission_texture_scales_the_factor(tmp_path):
    texture = np.zeros((4, 4, 3), np.uint8)
    texture[:, 2:] = 255  # transmissive where u >= 0.5 (x >= 1), opaque glass elsewhere
    state = read_scene(_glass(tmp_path / "half.glb", texture=texture)).pose(0)
    caster = RayCaster(state)
    down = np.tile([0.0, -1.0, 0.0], (2, 1)).astype(np.float32)
    stops = []
    for x in (0.5, 1.5):
        origins = np.tile([x, 3.0, 1.0], (2000, 1)).astype(np.float32)
        origins[:, 2] += np.linspace(-0.4, 0.4, 2000, dtype=np.float32)
        tri, *_ = caster.intersect(origins, np.tile(down[:1], (2000, 1)))
        stops.append((state.triangle_instance[tri] == 1).mean())
    assert stops[0] == 1.0 and 0.02 < stops[1] < 0.07  # F0 = 0.04 where it transmits


@pytest.mark.parametrize("ext, value, match", [
    ("KHR_materials_transmission", {"transmissionFactor": 1.5}, r"transmissionFactor: must be in \[0, 1\]"),
    ("KHR_materials_ior", {"ior": 0.5}, r"ior: must be at least 1 \(or 0\)"),
    ("KHR_materials_transmission", {"transmissionFactor": "yes"}, r"transmissionFactor: must be a finite number"),
])
def test_bad_transmission_values_are_one_line_errors(tmp_path, ext, value, match):
    path = _glass(tmp_path / "bad.glb")
    g = GLTF2().load(str(path))
    g.materials[1].extensions[ext] = value
    g.save(str(path))
    with pytest.raises(SceneError, match=r"materials\[1\].extensions\." + ext + r"\." + match) as err:
        read_scene(path)
    assert "\n" not in str(err.value)


def test_a_camera_sees_a_sunlit_floor_through_glass_at_one_minus_f0_squared(tmp_path):
    # Sun and camera straight above: the shadow ray and the camera ray each pass the pane with
    # probability 1 - F0 (0.96 at ior 1.5); what the camera meets reflected is the empty sky
    direct = []
    for name, pane in (("bare", False), ("glass", True)):
        b = GltfBuilder()
        white = b.add_material("white", (0.7, 0.7, 0.7))
        b.add_node("floor", b.add_mesh("floor", QUAD * [4, 1, 4] - [3, 0, 3], QUAD_FACES, material=white))
        if pane:
            glass = b.add_material("glass", (1.0, 1.0, 1.0), roughness=0.0)
            b.gltf.materials[glass].extensions["KHR_materials_transmission"] = {"transmissionFactor": 1.0}
            b._use_extension("KHR_materials_transmission")
            b.add_node("pane", b.add_mesh("pane", QUAD * [4, 1, 4] - [3, 0, 3], QUAD_FACES, material=glass),
                       translation=(0, 1, 0))
        b.add_node("sun", light=b.add_directional_light("sun", (1, 1, 1), 3.0), rotation=(-0.7071068, 0, 0, 0.7071068))
        b.add_node("cam", camera=b.add_camera("cam", 0.6, 0.05), translation=(1, 3, 1),
                   rotation=(-0.7071068, 0, 0, 0.7071068))
        path = b.write(tmp_path / f"{name}.glb")
        out = tmp_path / name
        result = CliRunner().invoke(main, ["render", str(path), "--out", str(out), "--frames", "1", "--photons", "2000",
                                           "--temporal", "off", "--resolution", "32x24", "--spp", "8",
                                           "--scheduler", "synchronous", "--quiet"])
        assert result.exit_code == 0, result.output
        direct.append(read_exr(frame_paths(out, 1)[0])[0]["direct.R"])
    assert (direct[0] > 0).all()  # the floor fills the frame
    ratio = direct[1].mean() / direct[0].mean()
    assert abs(ratio - 0.96 ** 2) < 0.02, ratio  # 768 pixels x 8 samples: binomial sd about 0.003


def test_vertex_colour_alpha_cuts_and_blends_as_its_interpolation_says(tmp_path):
    # The sheet's COLOR_0 alpha runs 0 at x = 0 to 1 at x = 2 (QUAD's corners): a mask of cut-off
    # 0.5 has its hole where x < 1, a blend stops x / 2 of the rays meeting it at x
    alpha = QUAD[:, 0] / 2
    colors = np.c_[np.ones((4, 3)), alpha]
    for mode in ("MASK", "BLEND"):
        b = basic_builder()
        mat = b.add_material("fade", (0.5, 0.5, 0.5), alpha_mode=mode, alpha_cutoff=0.5 if mode == "MASK" else None)
        b.add_node("sheet", b.add_mesh("sheet", QUAD, QUAD_FACES, material=mat, colors=colors),
                   translation=(0, SHEET_Y, 0))
        state = read_scene(b.write(tmp_path / f"{mode}.glb")).pose(0)
        caster = RayCaster(state)
        for x in (0.5, 1.5):
            n = 20_000 if mode == "BLEND" else 50
            z = np.linspace(0.2, 1.8, n)
            origins = np.c_[np.full(n, x), np.full(n, 3.0), z].astype(np.float32)
            tri, *_ = caster.intersect(origins, np.tile([0.0, -1.0, 0.0], (n, 1)).astype(np.float32))
            stopped = (state.triangle_instance[tri] == 1).mean()
            want = (x > 1) if mode == "MASK" else x / 2
            assert abs(stopped - want) < (0.02 if mode == "BLEND" else 1e-9), (mode, x, stopped)
