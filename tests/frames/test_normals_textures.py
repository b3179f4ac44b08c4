"""Vertex normals and base-colour textures end to end (real Embree, OpenCL, OpenImageIO).

Scenes are written here with the real builder: a smooth UV sphere under a directional light against
the analytic Lambert value; a checkerboard texture on a plane, in the frame and in the colour its
photons bleed onto a white wall; a texture transform's offset; the furnace with a constant texture;
an emissive texture on an area light, in photons, in the frame and in the area lighting.
Expected values are evaluated at the compositor's own jittered sample directions
(kernels/camera.py), so the comparisons carry no sampling error.
"""
from __future__ import annotations

import numpy as np
import pytest

from kernels.camera import camera_rays_reference
from pipeline.config import PhotonConfig
from pipeline.frames.camera_paths import CameraPaths, render_frame
from pipeline.frames.random_numbers import frame_key
from pipeline.photons.raycast import caster_for
from pipeline.photons.tracing import PhotonRange, trace_batch
from pipeline.scene import ElementMesh, read_scene
from pipeline.scene.builtin import shapes
from pipeline.scene.builtin.gltf_builder import GltfBuilder
from pipeline.scene.summary import surface_lines
from pipeline.scene.textures import srgb_to_linear
from pipeline.store import DIRECT_BIT, ELEMENT_MASK
from tests.frames.scenes import UP_FACES

SUN = np.array([-0.4, -0.5, -1.0]) / np.linalg.norm([-0.4, -0.5, -1.0])  # direction the light travels
SUN_E = 3.0  # irradiance on a surface facing the sun
SEED = 3


def _sample_dirs(state, width, height, spp):
    cam = state.camera
    return camera_rays_reference(frame_key(SEED, 1), 0, width * height * spp, spp, width, height,
                                 cam.definition.yfov, cam.to_world[:3, :3]).astype(np.float64)


def _sphere_scene(path, smooth: bool, albedo=0.8):
    b = GltfBuilder()
    white = b.add_material("white", (albedo, albedo, albedo))
    mesh = shapes.uv_sphere(1.0, 24, 48)
    b.add_node("ball", b.add_mesh("ball", *mesh, material=white,
                                  normals=shapes.sphere_normals(mesh[0]) if smooth else None))
    b.add_node("sun", light=b.add_directional_light("sun", (1, 1, 1), SUN_E),
               rotation=shapes.look_at((0, 0, 0), SUN))
    b.add_node("cam", camera=b.add_camera("cam", 2 * np.arctan(0.3), 0.05), translation=(0.0, 0.0, 4.0))
    b.set_scene_extras({"photonloom": {"element_size": 0.5}})
    return b.write(path)


def _sphere_render(path, width=48, height=48, spp=8):
    """Direct layer and the analytic Lambert value rho/pi E max(0, n.l) with n the sphere's own
    normal at each sample's hit point on the mesh (pixel = mean of its samples)."""
    state = read_scene(path).pose_frame(1)
    img = render_frame(state, None, None, CameraPaths(width, height, spp, seed=SEED, frame=1))
    d = _sample_dirs(state, width, height, spp)
    origin = np.broadcast_to(state.camera.position, d.shape)
    tri, _, _, t = caster_for(state).intersect(origin, d)
    p = origin + t[:, None].astype(np.float64) * d
    n = p / np.linalg.norm(p, axis=1, keepdims=True)
    cos = np.where(tri >= 0, np.maximum(n @ -SUN, 0.0), np.nan)
    cos = cos.reshape(height, width, spp)
    expected = 0.8 / np.pi * SUN_E * cos.mean(axis=2)
    return img.direct[..., 1].astype(np.float64), expected, cos.min(axis=2)


def test_uv_sphere_with_normals_renders_smooth(tmp_path):
    smooth, expected, cos_min = _sphere_render(_sphere_scene(tmp_path / "smooth.glb", True))
    flat, _, _ = _sphere_render(_sphere_scene(tmp_path / "flat.glb", False))
    known = cos_min > 0.25  # every sample of the pixel on the sphere, well inside the lit side
    assert known.sum() > 500
    err_smooth = np.abs(smooth[known] / expected[known] - 1)
    err_flat = np.abs(flat[known] / expected[known] - 1)
    assert err_smooth.max() < 0.01, err_smooth.max()  # analytic Lambert within 1 %
    assert err_flat.max() > 0.03  # facets: the test can tell flat from smooth
    # continuity: steps between neighbouring pixels are the analytic image's own steps (no jumps
    # at face edges), to a small fraction of the facets' jumps
    both = known[:, 1:] & known[:, :-1]
    true_step = np.diff(expected, axis=1)[both]
    jump_smooth = np.abs(np.diff(smooth, axis=1)[both] - true_step).max()
    jump_flat = np.abs(np.diff(flat, axis=1)[both] - true_step).max()
    assert jump_smooth < 0.2 * jump_flat, (jump_smooth, jump_flat)


def test_vertex_normals_follow_a_non_uniform_scale(tmp_path):
    """NORMAL transforms by the inverse transpose: a sphere squashed to an ellipsoid keeps normals
    perpendicular to its surface (the plain matrix would tilt them towards the squash)."""
    b = GltfBuilder()
    mesh = shapes.uv_sphere(1.0, 12, 24)
    b.add_node("egg", b.add_mesh("egg", *mesh, material=b.add_material("w", (0.5, 0.5, 0.5)),
                                 normals=shapes.sphere_normals(mesh[0])), scale=(2.0, 0.5, 1.0))
    b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), 1.0), translation=(0, 3, 0))
    state = read_scene(b.write(tmp_path / "egg.glb")).pose_frame(1)
    p = state.vertices.astype(np.float64)[state.faces]  # (F, 3, 3) world corners on x^2/4 + 4 y^2 + z^2 = 1
    gradient = p * [0.25, 4.0, 1.0]
    gradient /= np.linalg.norm(gradient, axis=2, keepdims=True)
    np.testing.assert_allclose(state.corner_normals, gradient, atol=1e-5)


# --- textures -----------------------------------------------------------------------------------
CELLS = 8  # checker cells per side of the texture
HALF = 2.0  # the plane spans [-HALF, HALF]^2 at y = 0, uv = (x, z) mapped to [0, 1]^2
RED, GREEN = np.array([230, 20, 20]), np.array([20, 230, 20])


def _checker_pixels(texels_per_cell=4):
    i, j = np.meshgrid(np.arange(CELLS * texels_per_cell), np.arange(CELLS * texels_per_cell), indexing="ij")
    odd = ((i // texels_per_cell + j // texels_per_cell) % 2).astype(bool)
    return np.where(odd[..., None], GREEN, RED).astype(np.uint8)


def _checker_plane(b, transform=None, uri=None):
    tex = b.add_texture(_checker_pixels(), mag_filter=9728, uri=uri)  # NEAREST: crisp cells
    mat = b.add_material("checker", (1.0, 1.0, 1.0), base_color_texture=tex, texture_transform=transform)
    quad = np.array([[-HALF, 0, -HALF], [HALF, 0, -HALF], [HALF, 0, HALF], [-HALF, 0, HALF]], float)
    uv = (quad[:, [0, 2]] + HALF) / (2 * HALF)
    b.add_node("floor", b.add_mesh("floor", quad, UP_FACES, material=mat, texcoords={0: uv}))


def _top_view(path, transform=None):
    b = GltfBuilder()
    _checker_plane(b, transform)
    b.add_node("sun", light=b.add_directional_light("sun", (1, 1, 1), 1.0),
               rotation=shapes.look_at((0, 0, 0), (0, -1, 0), (0, 0, -1)))
    eye = np.array([0.0, 3.0, 0.0])
    b.add_node("cam", camera=b.add_camera("cam", 2 * np.arctan(HALF * 0.9 / 3.0), 0.05), translation=tuple(eye),
               rotation=shapes.look_at(eye, (0, 0, 0), (0, 0, -1)))
    b.set_scene_extras({"photonloom": {"element_size": 1.0}})
    return b.write(path)


def _expected_cells(state, width, height, spp, offset=(0.0, 0.0)):
    """Per pixel: 1 green, 0 red, -1 when its samples fall in different cells; sample uv from the
    camera ray meeting y = 0, then uv + offset (the texture transform)."""
    d = _sample_dirs(state, width, height, spp)
    o = state.camera.position
    p = o + (-o[1] / d[:, 1])[:, None] * d
    uv = (p[:, [0, 2]] + HALF) / (2 * HALF) + offset
    cell = np.floor(uv * CELLS).astype(np.int64)
    green = (cell.sum(axis=1) % 2).reshape(height, width, spp)
    return np.where(green.min(axis=2) == green.max(axis=2), green[..., 0], -1)


@pytest.mark.parametrize("offset", [None, (0.3 / CELLS, 0.0)])
def test_checker_texture_in_the_frame_and_its_transform(tmp_path, offset):
    """The albedo layer shows the checker, cell by cell, at the sample positions; with
    KHR_texture_transform's offset the cells move by exactly that offset in uv."""
    transform = None if offset is None else {"offset": list(offset)}
    state = read_scene(_top_view(tmp_path / "top.glb", transform)).pose_frame(1)
    w = h = 64
    img = render_frame(state, None, None, CameraPaths(w, h, 4, seed=SEED, frame=1))
    want = _expected_cells(state, w, h, 4, offset or (0.0, 0.0))
    inside = want >= 0
    assert inside.mean() > 0.7
    red, green = srgb_to_linear(RED / 255.0), srgb_to_linear(GREEN / 255.0)
    expected = np.where(want[..., None] == 1, green, red)
    np.testing.assert_allclose(img.albedo[inside], expected[inside], rtol=1e-5)
    # direct light: rho/pi E under a sun straight above
    np.testing.assert_allclose(img.direct[inside], expected[inside] / np.pi, rtol=1e-4)
    if offset is not None:  # the shift is visible: the untransformed checker no longer fits
        unshifted = _expected_cells(state, w, h, 4)
        both = inside & (unshifted >= 0)
        assert (unshifted[both] != want[both]).mean() > 0.2


def test_colour_bleeding_follows_the_checker(tmp_path):
    """Photons reflected by the checker floor carry the colour of the cell they left: on a white
    wall standing along the floor's edge, indirect photons are redder above red cells and greener
    above green ones, alternating with the checker along the wall."""
    b = GltfBuilder()
    _checker_plane(b)
    white = b.add_material("wall", (0.8, 0.8, 0.8))
    # the wall x in [-HALF, HALF], y in [0, 1], at z = -HALF, facing +z (towards the floor)
    wall = np.array([[-HALF, 0, -HALF], [HALF, 0, -HALF], [HALF, 1.0, -HALF], [-HALF, 1.0, -HALF]], float)
    b.add_node("wall", b.add_mesh("wall", wall, np.array([0, 1, 2, 0, 2, 3]), material=white))
    b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), 20.0), translation=(0.0, 2.0, 0.5))
    b.set_scene_extras({"photonloom": {"element_size": 0.05}})
    scene = read_scene(b.write(tmp_path / "bleed.glb"))
    elements, state = ElementMesh.build(scene), scene.pose_frame(1)
    batch = trace_batch(state, elements, PhotonRange(1, 0, 400_000), PhotonConfig(seed=5, photon_depth=2))
    elem = (batch.key & ELEMENT_MASK).astype(np.int64)
    centre = elements.element_positions(state)[elem].mean(axis=1)
    on_wall = (np.abs(centre[:, 2] + HALF) < 1e-6) & ((batch.key & DIRECT_BIT) == 0) & (centre[:, 1] < 0.3)
    x = centre[on_wall, 0]
    e = batch.energy[on_wall].astype(np.float64)
    # per checker column along the wall (the row of cells next to it, z cell 0): redness R / (R + G)
    column = np.floor((x + HALF) / (2 * HALF) * CELLS).astype(np.int64)
    red_sum = np.bincount(column, weights=e[:, 0], minlength=CELLS)
    green_sum = np.bincount(column, weights=e[:, 1], minlength=CELLS)
    redness = red_sum / (red_sum + green_sum)
    cell_is_red = np.arange(CELLS) % 2 == 0  # cell (column, 0) is red when column is even
    assert (redness[cell_is_red] > 0.55).all() and (redness[~cell_is_red] < 0.45).all(), redness


def _box_faces():
    v = np.array([[x, y, z] for x in (0, 2.0) for y in (0, 2.0) for z in (0, 2.0)], float)
    faces = np.array([[0, 1, 3, 0, 3, 2], [4, 6, 7, 4, 7, 5], [0, 4, 5, 0, 5, 1],
                      [2, 3, 7, 2, 7, 6], [0, 2, 6, 0, 6, 4], [1, 5, 7, 1, 7, 3]]).ravel()
    return v, faces


def _furnace(path, level: int, textured: bool):
    """A closed 2 m box of albedo rho: a constant texture of sRGB ``level`` with factor 1, or no
    texture with the factor rho = that texel's linear value (float32, as the decoder makes it)."""
    rho = float(np.float32(srgb_to_linear(level / 255.0)))
    b = GltfBuilder()
    v, faces = _box_faces()
    if textured:
        tex = b.add_texture(np.full((4, 4, 3), level, np.uint8))
        mat = b.add_material("grey", (1.0, 1.0, 1.0), base_color_texture=tex)
        uv = v[:, :2] / 2.0
        b.add_node("box", b.add_mesh("box", v, faces, material=mat, texcoords={0: uv}))
    else:
        b.add_node("box", b.add_mesh("box", v, faces, material=b.add_material("grey", (rho, rho, rho))))
    b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), 3.0), translation=(1.0, 1.1, 0.9))
    b.set_scene_extras({"photonloom": {"element_size": 0.5}})
    return b.write(path), rho


N_FURNACE = 15_000  # photons in each of 16 independent batches


def test_furnace_with_a_constant_texture_equals_the_factor(tmp_path):
    """Indirect energy in a closed box is Phi rho / (1 - rho) (the furnace); a constant texture gives
    the same photons as the same albedo given as a factor, and the same frame."""
    out = {}
    for textured in (False, True):
        path, rho = _furnace(tmp_path / f"furnace{int(textured)}.glb", 188, textured)
        scene = read_scene(path)
        elements, state = ElementMesh.build(scene), scene.pose_frame(1)
        batches = [trace_batch(state, elements, PhotonRange(1, k * N_FURNACE, N_FURNACE),
                               PhotonConfig(seed=7, photon_depth=200)) for k in range(16)]
        out[textured] = batches
    phi = 4 * np.pi * 3.0
    for a, b in zip(out[False], out[True]):
        np.testing.assert_array_equal(a.key, b.key)
        np.testing.assert_allclose(a.energy, b.energy, rtol=1e-6)
    indirect = [bt.energy[(bt.key & DIRECT_BIT) == 0, 0].astype(np.float64).sum() / N_FURNACE
                for bt in out[True]]
    mean, se = np.mean(indirect), np.std(indirect, ddof=1) / np.sqrt(len(indirect))
    expected = phi * rho / (1 - rho)
    assert abs(mean - expected) <= 3 * se + 1e-9 and se < 0.05 * expected, (mean, expected, se)


# --- emissive textures ----------------------------------------------------------------------------
PANEL_H, PANEL_L = 1.0, 3.0  # height of the 1 m x 1 m panel facing down, radiance of its white texels
DOWN_FACES = np.array([0, 1, 2, 0, 2, 3])  # CCW seen from below: the front face looks down


def _panel_scene(path, textured: bool, look_up: bool = True):
    """A grey floor under a square panel [-0.5, 0.5]^2 at PANEL_H: either the whole panel with an
    emissive texture white on x < 0 and black on x > 0, or only its x < 0 half emitting PANEL_L
    uniformly. Both emit the same light from the same place. Camera below it, looking up at the
    panel or down at the floor."""
    b = GltfBuilder()
    grey = b.add_material("floor", (0.5, 0.5, 0.5))
    b.add_node("floor", b.add_mesh("floor", np.array([[-10, 0, -10], [10, 0, -10], [10, 0, 10], [-10, 0, 10]], float),
                                   UP_FACES, material=grey))
    x1 = 0.5 if textured else 0.0
    quad = np.array([[-0.5, PANEL_H, -0.5], [x1, PANEL_H, -0.5], [x1, PANEL_H, 0.5], [-0.5, PANEL_H, 0.5]], float)
    if textured:
        pixels = np.zeros((8, 8, 3), np.uint8)
        pixels[:, :4] = 255  # u < 0.5 (x < 0) white
        tex = b.add_texture(pixels, mag_filter=9728)
        glow = b.add_material("glow", (0, 0, 0), emissive=(1, 1, 1), emissive_strength=PANEL_L, emissive_texture=tex)
        b.add_node("panel", b.add_mesh("panel", quad, DOWN_FACES, material=glow,
                                       texcoords={0: quad[:, [0, 2]] + 0.5}))
    else:
        glow = b.add_material("glow", (0, 0, 0), emissive=(1, 1, 1), emissive_strength=PANEL_L)
        b.add_node("panel", b.add_mesh("panel", quad, DOWN_FACES, material=glow))
    eye = np.array([0.0, 0.3 if look_up else 0.9, 0.0])
    target = (0, PANEL_H, 0) if look_up else (0, 0, 0)
    b.add_node("cam", camera=b.add_camera("cam", 2 * np.arctan(0.5 / 0.7 * 0.9), 0.05), translation=tuple(eye),
               rotation=shapes.look_at(eye, target, (0, 0, -1)))
    b.set_scene_extras({"photonloom": {"element_size": 0.5}})
    return b.write(path)


def test_emissive_texture_emits_where_its_texels_are_bright(tmp_path):
    """Photons: the half-white textured panel sends the same flux to the same places as a uniform
    panel of its white half (floor energy on either side of x = 0, within 3 standard errors)."""
    n, k = 20_000, 8
    sums = {}
    for textured in (True, False):
        scene = read_scene(_panel_scene(tmp_path / f"panel{int(textured)}.glb", textured))
        elements, state = ElementMesh.build(scene), scene.pose_frame(1)
        rows = []
        for j in range(k):
            bt = trace_batch(state, elements, PhotonRange(1, j * n, n), PhotonConfig(seed=11, photon_depth=1))
            x = elements.element_positions(state)[(bt.key & ELEMENT_MASK).astype(np.int64)].mean(axis=1)[:, 0]
            e = bt.energy[:, 0].astype(np.float64) / n
            rows.append([e[x < 0].sum(), e[x >= 0].sum()])
        sums[textured] = np.array(rows)
    flux_half = np.pi * PANEL_L * 0.5  # pi L A of the white half
    for side in (0, 1):
        a, b = sums[True][:, side], sums[False][:, side]
        se = np.hypot(a.std(ddof=1), b.std(ddof=1)) / np.sqrt(k)
        assert abs(a.mean() - b.mean()) <= 3 * se, (side, a.mean(), b.mean(), se)
    total = sums[True].sum(axis=1).mean()
    assert 0.97 * flux_half < total <= flux_half * 1.01  # a few per cent pass the floor's edges


def test_emissive_texture_in_the_frame(tmp_path):
    """Seen from below, the panel shows PANEL_L on its white half and nothing on its black half."""
    w = h = 32
    scene = read_scene(_panel_scene(tmp_path / "panel.glb", True))
    assert "no base-colour textures; emissive textures on 1 material(s)" in surface_lines(scene)[0]
    state = scene.pose_frame(1)
    img = render_frame(state, None, None, CameraPaths(w, h, 1, seed=SEED, frame=1))
    d = _sample_dirs(state, w, h, 1)
    o = state.camera.position
    p = (o + ((PANEL_H - o[1]) / d[:, 1])[:, None] * d).reshape(h, w, 3)
    on_panel = (np.abs(p[..., 0]) < 0.5) & (np.abs(p[..., 2]) < 0.5)
    white, black = on_panel & (p[..., 0] < -0.02), on_panel & (p[..., 0] > 0.02)
    assert white.sum() > 50 and black.sum() > 50
    np.testing.assert_allclose(img.direct[white], PANEL_L, rtol=1e-6)
    assert (img.direct[black] == 0).all()


def test_emissive_texture_in_area_lighting(tmp_path):
    """The floor under the half-white textured panel gets the area lighting of the uniform half
    panel: direct layers agree on either side of x = 0 (64 area samples x 4 spp a pixel)."""
    w = h = 32
    out = {}
    for textured in (True, False):
        state = read_scene(_panel_scene(tmp_path / f"down{int(textured)}.glb", textured, look_up=False)).pose_frame(1)
        img = render_frame(state, None, None, CameraPaths(w, h, 4, seed=SEED, frame=1, area_samples=64))
        out[textured] = img.direct[..., 0].astype(np.float64)
    left, right = np.s_[:, : w // 2 - 1], np.s_[:, w // 2 + 1:]  # the camera's x is the world's x
    for half in (left, right):
        assert abs(out[True][half].mean() / out[False][half].mean() - 1) < 0.02
    assert out[True][left].mean() > 1.3 * out[True][right].mean()  # brighter under the white half
