"""Build a :class:`~pipeline.scene.scene.Scene` from a parsed glTF document, validating as it goes.

Every refusal is a one-line :class:`SceneError` naming the file and the glTF field. Skins
(``JOINTS_n``/``WEIGHTS_n``, inverse bind matrices) and morph targets (POSITION and NORMAL
displacements, default and animated weights) are read here into each instance's
:class:`~pipeline.scene.deform.Deformation`; the scene poses them per frame.
"""
from __future__ import annotations

import hashlib
import logging
from dataclasses import replace
from pathlib import Path

import numpy as np

from .animation import INTERPOLATIONS, PATHS, Deformation, Sampler, Skin, normalise_weights
from .camera import AUTO, CameraDef
from .default_camera import AZIMUTH, ELEVATION, YFOV_DEG, animation_bounds, frame_animation, sample_frames
from .default_lights import default_sky, default_sun
from .draco import decode_primitives
from .elements import MAX_ELEMENTS
from .environment import EnvironmentMap
from .gltf import GltfDocument, read_gltf
from .instancing import EXTENSION as INSTANCING
from .instancing import instance_transforms, place_copy
from .lights import light_def_from_gltf
from .materials import DEFAULT_MATERIAL, IOR, TRANSMISSION, VOLUME, any_emits, material_from_gltf
from .meshopt import decode_views
from .nodes import MeshInstance, Node
from .pointers import ANIMATED_POINTERS, BOOLEAN_ACCESSOR, NON_NEGATIVE_PROPERTIES, WIDTHS, pointer_target
from .pointers import EXTENSION as POINTER
from .scene import DEFAULT_ELEMENT_FRACTION, Scene
from .textures import (
    base_color_texture,
    emissive_texture,
    metallic_roughness_texture,
    normal_texture,
    transmission_texture,
)
from .timeline import DEFAULT_FPS, MAX_FRAMES, Timeline
from .variants import apply_variant
from .vertex_attributes import read_vertex_attributes
from .visibility import EXTENSION as VISIBILITY
from .visibility import always_hidden

log = logging.getLogger(__name__)
# What the loader chose for a file that lacks it (default camera, default lights): the CLI shows
# this logger's INFO lines (pipeline/cli/__init__.py); Dask workers, which load the scene again, do not.
notices_log = logging.getLogger("pipeline.scene.notices")
_noticed: set[tuple[str, str]] = set()  # one notice per file and process
LIGHT_CHOICES = ("auto", "none")  # --light: a default sun and sky for a file without light, or refuse it
ALPHA_MODES = ("OPAQUE", "MASK", "BLEND")  # glTF 2.0 §5.19 material.alphaMode

# Primitive modes (glTF §3.7.2.1): 4 TRIANGLES, 5 TRIANGLE_STRIP, 6 TRIANGLE_FAN.
_TRIANGLE_MODES = {4, 5, 6}
_INDEX_COMPONENTS = (5121, 5123, 5125)  # indices are UNSIGNED_BYTE, UNSIGNED_SHORT or UNSIGNED_INT (§3.7.2.1)
_MODE_NAMES = {0: "POINTS", 1: "LINES", 2: "LINE_LOOP", 3: "LINE_STRIP"}
# Triangles whose area is below this fraction of the squared bounding-box diagonal are "zero-area".
_ZERO_AREA = 1e-14
# Frames whose posed bounds give the default element size (evenly spread over the timeline)
ELEMENT_SIZE_FRAMES = 256
# JOINTS_n are unsigned bytes or shorts, WEIGHTS_n floats or normalized unsigned bytes or shorts (§3.7.3.1)
_JOINT_COMPONENTS = (5121, 5123)
_WEIGHT_COMPONENTS = (5126, 5121, 5123)


def read_scene(path: str | Path, *, camera: str | None = None, fps: float | None = None,
               light: str = "auto", animation: str | None = None, variant: str | None = None,
               environment: EnvironmentMap | None = None) -> Scene:
    """Load a ``.glb``/``.gltf`` file. ``camera`` picks a camera by camera or node name, or
    ``auto`` (pipeline/scene/default_camera.py); ``light`` ``auto`` lights a file without light
    with the default sun and sky (pipeline/scene/default_lights.py), ``none`` refuses it;
    ``animation`` names the animation that plays first (the file's first when None); ``variant``
    the material variant (pipeline/scene/variants.py; None: the primitives' own materials);
    ``environment`` an image-based light around the scene (pipeline/scene/environment.py), in
    place of the default sun and sky."""
    return build_scene(read_gltf(path), camera=camera, fps=fps, light=light, animation=animation, variant=variant,
                       environment=environment)


def build_scene(doc: GltfDocument, *, camera: str | None = None, fps: float | None = None,
                light: str = "auto", animation: str | None = None, variant: str | None = None,
                environment: EnvironmentMap | None = None) -> Scene:
    if light not in LIGHT_CHOICES:
        raise ValueError(f"light must be one of {LIGHT_CHOICES}, got {light!r}")
    if variant is not None:
        apply_variant(doc, variant)
    if environment is not None:  # another light is another scene: its photons are not the file's alone
        doc.digest = hashlib.sha256(f"{doc.digest}\0environment\0{environment.digest}".encode()).hexdigest()
    g = doc.gltf
    warnings: list[str] = []
    notices: list[str] = []
    doc.views.update(decode_views(doc))  # meshoptimizer-compressed buffer views, read as their bytes
    doc.decoded.update(decode_primitives(doc))  # Draco-compressed primitives, read as their accessors
    nodes = _read_nodes(doc)
    order = _reachable(doc, nodes)

    for i, m in enumerate(g.materials):
        _check_material(doc, m, i)
    materials = [material_from_gltf(m, i) for i, m in enumerate(g.materials)]
    materials = _with_textures(doc, materials)
    default_material = len(materials)
    materials.append(DEFAULT_MATERIAL)

    light_defs = []
    raw_lights = (g.extensions or {}).get("KHR_lights_punctual", {}).get("lights", [])
    for i, raw in enumerate(raw_lights):
        try:
            light_defs.append(light_def_from_gltf(raw, i))
        except (ValueError, TypeError) as err:
            raise doc.error(str(err), f"extensions.KHR_lights_punctual.lights[{i}]") from None
    for i in order:
        if nodes[i].light is not None and not 0 <= nodes[i].light < len(light_defs):
            raise doc.error(f"refers to missing light {nodes[i].light}", f"nodes[{i}].extensions.KHR_lights_punctual")

    cameras = []
    for i, cam in enumerate(g.cameras):
        if cam.type == "orthographic" and cam.orthographic is not None:
            o = cam.orthographic
            if not (o.ymag and o.xmag and np.isfinite(o.ymag) and np.isfinite(o.xmag)):
                raise doc.error(f"xmag {o.xmag} and ymag {o.ymag} must be finite and not zero",
                                f"cameras[{i}].orthographic")
            cameras.append(CameraDef(cam.name or f"camera{i}", 0.0, float(o.znear or 0.0),
                                     float(o.zfar) if o.zfar else None, abs(float(o.xmag / o.ymag)),
                                     ymag=abs(float(o.ymag))))
            continue
        if cam.type != "perspective" or cam.perspective is None:
            cameras.append(None)  # neither a pinhole nor orthographic: listed, never chosen
            continue
        p = cam.perspective
        if not (p.yfov and 0 < p.yfov < np.pi and p.znear and p.znear > 0):
            raise doc.error(f"yfov {p.yfov} and znear {p.znear} must be positive (yfov < pi)",
                            f"cameras[{i}].perspective")
        cameras.append(CameraDef(cam.name or f"camera{i}", float(p.yfov), float(p.znear),
                                 float(p.zfar) if p.zfar else None,
                                 float(p.aspectRatio) if p.aspectRatio else None))

    channels, played, left_out, default = _read_channels(doc, nodes, warnings, animation)
    visibility = {i: ch["visible"] for i, ch in _by_target(channels, "visibility").items()}
    hidden = always_hidden(nodes, order, visibility)
    shown = [i for i in order if i not in hidden]
    skins = _read_skins(doc, order)
    instances, dropped = _read_instances(doc, nodes, shown, default_material, warnings, skins)
    _texcoord_warnings(materials, instances, warnings)
    if not instances:
        raise doc.error("the scene has no triangle meshes" + (" that are ever visible (KHR_node_visibility)"
                                                              if hidden else ""), "meshes")
    animated_materials = _by_target(channels, "material")
    emissive = any_emits(materials, g.materials, animated_materials, {inst.material for inst in instances})
    unlit = not any(nodes[i].light is not None for i in shown) and not emissive and environment is None
    if unlit and light == "none":
        raise doc.error("the scene has no light: no KHR_lights_punctual light on a node and no emissive material "
                        "(--light auto lights it with a default sun and sky)", "lights")
    if unlit:
        hidden_lights = any(nodes[i].light is not None for i in hidden)
        notices.append(("the file's lights are on nodes hidden throughout (KHR_node_visibility)" if hidden_lights
                        else "the file has no light") + ": lit by the default sun and sky of "
                       "pipeline/scene/default_lights.py (loom info describes them; --light none refuses such a file)")

    if left_out:
        notices.append(f"{len(left_out)} animation(s) animate nodes that {played[0]!r} animates, alternative clips "
                       f"played one at a time: playing {', '.join(map(repr, played))}, leaving out "
                       f"{', '.join(map(repr, left_out))} (--animation NAME plays another first)")
    extras = _scene_extras(doc)
    fps, n_frames = _timeline_numbers(doc, extras, channels.values(), fps)

    camera_node = _choose_camera(doc, nodes, order, cameras, camera)

    element_size = extras.get("element_size")
    if element_size is not None and not _is_number(element_size):
        raise doc.error(f"element_size {element_size!r} must be a number", "scenes.extras.photonloom.element_size")
    if element_size is not None and not float(element_size) > 0:
        raise doc.error(f"element_size {element_size} must be positive", "scenes.extras.photonloom.element_size")

    if dropped:
        warnings.append(f"dropped {dropped} zero-area triangle(s)")
    for w in warnings:
        log.warning("%s: %s", doc.path, w)
    scene = Scene(
        path=doc.path, document=doc, nodes=nodes, order=order, instances=instances,
        materials=materials, light_defs=light_defs, cameras=cameras, channels=_by_target(channels, "node"),
        light_channels=_by_target(channels, "light"), material_channels=animated_materials,
        camera_channels=_by_target(channels, "camera"), visibility_channels=visibility,
        hidden_nodes=frozenset(hidden),
        timeline=Timeline(fps=fps, frames=int(n_frames)), camera_node=camera_node,
        element_size=float(element_size or 0.0), dropped_triangles=dropped, warnings=warnings, notices=notices,
        animations_played=tuple(played), animations_left_out=tuple(left_out),
        animation_option=None if played == default else played[0], variant_option=variant,
        default_lights=(default_sun(),) if unlit else (),
        sky=environment if environment is not None else (default_sky() if unlit else None),
    )
    if camera_node is None:  # --camera auto, or the file has no camera that renders
        scene.framing = frame_animation(scene)
        if camera != AUTO:
            notices.insert(0, f"the file has no camera: rendering with the auto camera from azimuth "
                              f"{AZIMUTH:g} deg, elevation {ELEVATION:g} deg, yfov {YFOV_DEG:g} deg, framing the "
                              "whole animation (--camera auto chooses it for any file)")
    if element_size is None:
        scene.element_size = _default_element_size(doc, scene)
    for n in notices:
        if (str(doc.path), n) not in _noticed:
            _noticed.add((str(doc.path), n))
            notices_log.info("%s: %s", doc.path, n)
    return scene


def _default_element_size(doc, scene: Scene) -> float:
    """DEFAULT_ELEMENT_FRACTION of the diagonal of the world-space bounds of every mesh, posed
    (node matrices, skins, morphs) at up to ELEMENT_SIZE_FRAMES frames spread over the timeline: what
    the camera and the photons see, not the vertices as the file stores them."""
    if scene.framing is not None:
        lo, hi = scene.framing.lo, scene.framing.hi
    else:
        lo, hi = animation_bounds(scene, sample_frames(scene.timeline, ELEMENT_SIZE_FRAMES))
    with np.errstate(over="ignore", invalid="ignore"):
        size = float(np.linalg.norm(hi - lo)) * DEFAULT_ELEMENT_FRACTION
    if not (np.isfinite(size) and size > 0):
        raise doc.error(f"the posed meshes span {lo.tolist()}..{hi.tolist()} in world space, which gives no "
                        "default element size; state one (scenes.extras.photonloom.element_size or "
                        "--element-size)", "nodes")
    return size


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and bool(np.isfinite(value))


def _timeline_numbers(doc, extras: dict, samplers, fps: float | None) -> tuple[float, int]:
    """fps and the number of frames: the caller's fps, else the scene's, else 30; the scene's
    frames, else one past the last key. Each is checked (a stated 0 fps is an error, not 30), and
    the frames are refused above MAX_FRAMES before anything is planned per frame."""
    where = "scenes.extras.photonloom"
    if fps is None:
        fps = extras.get("fps", DEFAULT_FPS)
    if not _is_number(fps) or not fps > 0:
        raise doc.error(f"fps {fps!r} must be a positive number", where + ".fps")
    fps = float(fps)
    n_frames = extras.get("frames")
    if n_frames is not None:
        if isinstance(n_frames, float) and n_frames.is_integer():
            n_frames = int(n_frames)
        if isinstance(n_frames, bool) or not isinstance(n_frames, int):
            raise doc.error(f"frames {n_frames!r} must be an integer", where + ".frames")
        if not 1 <= n_frames <= MAX_FRAMES:
            raise doc.error(f"frames {n_frames} must be in [1, {MAX_FRAMES:,}]", where + ".frames")
        return fps, n_frames
    end = max((s.end for s in samplers), default=0.0)
    n_frames = round(end * fps) + 1 if end * fps < MAX_FRAMES else MAX_FRAMES + 1
    if n_frames > MAX_FRAMES:
        raise doc.error(f"the last animation key at {end:g} s gives {end * fps + 1:,.0f} frames at {fps:g} fps, "
                        f"more than {MAX_FRAMES:,}; state the frames to render in "
                        f"{where}.frames", "animations")
    return fps, int(n_frames)


def _check_material(doc, m, i: int) -> None:
    """Emission and factors in the ranges glTF gives them (shapes are checked in gltf_schema.py):
    a negative emission is an error of its own, not a scene "without light"."""
    f = f"materials[{i}]"
    if m.emissiveFactor is not None:
        if len(m.emissiveFactor) != 3 or min(m.emissiveFactor) < 0:
            raise doc.error(f"must be 3 non-negative numbers, got {list(m.emissiveFactor)}", f + ".emissiveFactor")
    strength = (m.extensions or {}).get("KHR_materials_emissive_strength", {}).get("emissiveStrength", 1.0)
    if strength < 0:
        raise doc.error(f"must be non-negative, got {strength}",
                        f + ".extensions.KHR_materials_emissive_strength.emissiveStrength")
    if m.alphaMode is not None and m.alphaMode not in ALPHA_MODES:
        raise doc.error(f"{m.alphaMode!r} is not one of {', '.join(ALPHA_MODES)}", f + ".alphaMode")
    extensions = m.extensions or {}
    t = extensions.get(TRANSMISSION, {}).get("transmissionFactor", 0.0)
    if not 0 <= t <= 1:
        raise doc.error(f"must be in [0, 1], got {t}", f"{f}.extensions.{TRANSMISSION}.transmissionFactor")
    ior = extensions.get(IOR, {}).get("ior", 1.5)
    if not (ior >= 1 or ior == 0) or ior == float("inf"):  # KHR_materials_ior: [1, inf) or 0
        raise doc.error(f"must be at least 1 (or 0), got {ior}", f"{f}.extensions.{IOR}.ior")
    volume = extensions.get(VOLUME, {})
    thickness = volume.get("thicknessFactor", 0.0)
    if not 0 <= thickness < float("inf"):
        raise doc.error(f"must be a non-negative number, got {thickness}", f"{f}.extensions.{VOLUME}.thicknessFactor")
    distance = volume.get("attenuationDistance", 1.0)
    if not distance > 0:
        raise doc.error(f"must be positive, got {distance}", f"{f}.extensions.{VOLUME}.attenuationDistance")
    color = volume.get("attenuationColor", [1.0, 1.0, 1.0])
    if len(color) != 3 or not all(0 <= c <= 1 for c in color):
        raise doc.error(f"must be 3 numbers in [0, 1], got {color}", f"{f}.extensions.{VOLUME}.attenuationColor")
    if m.alphaCutoff is not None and not m.alphaCutoff >= 0:
        raise doc.error(f"must be non-negative, got {m.alphaCutoff}", f + ".alphaCutoff")
    pbr = m.pbrMetallicRoughness
    if pbr is not None:
        if pbr.baseColorFactor is not None and len(pbr.baseColorFactor) not in (3, 4):
            raise doc.error(f"must be 4 numbers, got {len(pbr.baseColorFactor)}",
                            f + ".pbrMetallicRoughness.baseColorFactor")
        for name in ("metallicFactor", "roughnessFactor"):
            value = getattr(pbr, name)
            if value is not None and not 0 <= value <= 1:
                raise doc.error(f"must be in [0, 1], got {value}", f"{f}.pbrMetallicRoughness.{name}")


def _unit_quaternion(q: np.ndarray, doc, field: str) -> np.ndarray:
    """``q`` normalised; a (near) zero quaternion is no rotation at all and is refused."""
    norm = float(np.linalg.norm(q))
    if not norm > 1e-6:
        raise doc.error(f"rotation {q.tolist()} is not a unit quaternion (its length is {norm:g})", field)
    return q / norm


def _vec(value, default, n, doc, field):
    if value is None:
        return np.array(default, dtype=np.float64)
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (n,) or not np.all(np.isfinite(arr)):
        raise doc.error(f"must be {n} finite numbers, got {value!r}", field)
    return arr


def _read_nodes(doc: GltfDocument) -> list[Node]:
    g = doc.gltf
    parents: dict[int, int] = {}
    for i, n in enumerate(g.nodes):
        for c in n.children or []:
            if not 0 <= c < len(g.nodes):
                raise doc.error(f"child {c} does not exist", f"nodes[{i}].children")
            if c in parents:
                raise doc.error(f"node {c} has two parents ({parents[c]} and {i})", f"nodes[{i}].children")
            parents[c] = i
    _refuse_cycles(doc, parents)
    nodes = []
    for i, n in enumerate(g.nodes):
        f = f"nodes[{i}]"
        matrix = None
        if n.matrix is not None and list(n.matrix) != [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]:
            matrix = _vec(n.matrix, None, 16, doc, f + ".matrix").reshape(4, 4).T  # column-major
        light = (n.extensions or {}).get("KHR_lights_punctual", {}).get("light")
        visible = (n.extensions or {}).get(VISIBILITY, {}).get("visible", True)
        if not isinstance(visible, bool):
            raise doc.error(f"visible {visible!r} must be true or false", f"{f}.extensions.{VISIBILITY}.visible")
        if n.mesh is not None and not 0 <= n.mesh < len(g.meshes):
            raise doc.error(f"refers to missing mesh {n.mesh}", f + ".mesh")
        if n.camera is not None and not 0 <= n.camera < len(g.cameras):
            raise doc.error(f"refers to missing camera {n.camera}", f + ".camera")
        nodes.append(Node(
            index=i, name=n.name or f"node{i}", parent=parents.get(i), children=tuple(n.children or ()),
            translation=_vec(n.translation, (0, 0, 0), 3, doc, f + ".translation"),
            rotation=_unit_quaternion(_vec(n.rotation, (0, 0, 0, 1), 4, doc, f + ".rotation"), doc, f + ".rotation"),
            scale=_vec(n.scale, (1, 1, 1), 3, doc, f + ".scale"),
            matrix=matrix, mesh=n.mesh, camera=n.camera, light=light, visible=visible,
        ))
    return nodes


def _refuse_cycles(doc: GltfDocument, parents: dict[int, int]) -> None:
    """A node that is its own ancestor (glTF §3.5.3: the hierarchy is a set of disjoint trees)."""
    done: set[int] = set()
    for start in parents:
        path, seen, node = [], set(), start
        while node in parents and node not in done:
            if node in seen:
                loop = path[path.index(node):] + [node]
                raise doc.error(f"the node hierarchy has a cycle: {' -> '.join(map(str, loop))}", "nodes")
            seen.add(node)
            path.append(node)
            node = parents[node]
        done.update(path)


def _reachable(doc: GltfDocument, nodes: list[Node]) -> list[int]:
    """Nodes of the default scene, parents before children, depth first in file order."""
    g = doc.gltf
    if g.scenes:
        idx = g.scene if g.scene is not None else 0
        if not 0 <= idx < len(g.scenes):
            raise doc.error(f"default scene {idx} does not exist", "scene")
        roots = list(g.scenes[idx].nodes or [])
    else:
        roots = [n.index for n in nodes if n.parent is None]
    order, seen = [], set()
    stack = list(reversed(roots))
    while stack:
        i = stack.pop()
        if not 0 <= i < len(nodes):
            raise doc.error(f"node {i} does not exist", "scenes.nodes")
        if i in seen:
            raise doc.error(f"node {i} is reached twice (cycle or shared child)", "nodes")
        if nodes[i].parent is not None and nodes[i].parent not in seen:
            raise doc.error(f"root node {i} has a parent", "scenes.nodes")
        seen.add(i)
        order.append(i)
        stack.extend(reversed(nodes[i].children))
    return order


def _triangles(mode: int, idx: np.ndarray) -> np.ndarray:
    if mode == 4:
        return idx[: len(idx) // 3 * 3].reshape(-1, 3)
    if mode == 5:  # strip: flip every other triangle to keep the winding
        k = np.arange(len(idx) - 2)
        a, b, c = idx[k], idx[k + 1], idx[k + 2]
        odd = k % 2 == 1
        return np.stack([a, np.where(odd, c, b), np.where(odd, b, c)], axis=1)
    k = np.arange(1, len(idx) - 1)  # fan
    return np.stack([np.full(len(k), idx[0]), idx[k], idx[k + 1]], axis=1)


def _read_instances(doc, nodes, order, default_material, warnings, skins):
    g = doc.gltf
    instances: list[MeshInstance] = []
    dropped = 0
    for i in order:
        node = nodes[i]
        if node.mesh is None:
            continue
        skin = g.nodes[i].skin
        if skin is not None and not 0 <= skin < len(skins):
            raise doc.error(f"refers to missing skin {skin}", f"nodes[{i}].skin")
        mesh = g.meshes[node.mesh]
        copies = instance_transforms(doc, i)  # EXT_mesh_gpu_instancing: the mesh drawn once per copy
        for p, prim in enumerate(mesh.primitives):
            f = f"meshes[{node.mesh}].primitives[{p}]"
            mode = 4 if prim.mode is None else prim.mode
            if mode not in _TRIANGLE_MODES:
                raise doc.error(f"mode {_MODE_NAMES.get(mode, mode)} is not supported (triangles only)", f + ".mode")
            pos_index = getattr(prim.attributes, "POSITION", None)
            if pos_index is None:
                raise doc.error("has no POSITION attribute", f + ".attributes")
            verts = np.asarray(doc.accessor(pos_index, f + ".attributes.POSITION"), dtype=np.float64)
            if verts.ndim != 2 or verts.shape[1] != 3:
                raise doc.error("POSITION must be VEC3", f + ".attributes.POSITION")
            if not np.all(np.isfinite(verts)):
                bad = int(np.flatnonzero(~np.isfinite(verts).all(1))[0])
                raise doc.error(f"vertex {bad} has a NaN or Inf position", f + ".attributes.POSITION")
            if prim.indices is not None:
                idx = np.asarray(doc.accessor(prim.indices, f + ".indices", types=("SCALAR",),
                                              components=_INDEX_COMPONENTS)).astype(np.int64).ravel()
            else:
                idx = np.arange(len(verts), dtype=np.int64)
            if len(idx) and (idx.min() < 0 or idx.max() >= len(verts)):
                raise doc.error(f"index {int(idx.max())} is out of range for {len(verts)} vertices", f + ".indices")
            faces = _triangles(mode, idx)
            source = np.arange(len(faces))
            e1 = verts[faces[:, 1]] - verts[faces[:, 0]]
            e2 = verts[faces[:, 2]] - verts[faces[:, 0]]
            area2 = np.linalg.norm(np.cross(e1, e2), axis=1)
            diag = float(np.linalg.norm(verts.max(0) - verts.min(0))) if len(verts) else 0.0
            keep = area2 > _ZERO_AREA * max(diag, 1e-30) ** 2
            dropped += int((~keep).sum())
            if not keep.any():
                continue
            material = prim.material if prim.material is not None else default_material
            if not 0 <= material < len(g.materials) and material != default_material:
                raise doc.error(f"refers to missing material {material}", f + ".material")
            attributes = read_vertex_attributes(doc, prim.attributes, len(verts), f)
            deformation = _read_deformation(doc, i, node.mesh, prim, f, len(verts),
                                             None if skin is None else skins[skin], warnings)
            name = f"{node.name}/{mesh.name or f'mesh{node.mesh}'}[{p}]"
            if copies is None:
                instances.append(MeshInstance(
                    index=len(instances), node=i, mesh=node.mesh, primitive=p, name=name,
                    vertices=verts, faces=faces[keep], material=material, source_faces=source[keep],
                    attributes=None if attributes.empty else attributes, deformation=deformation,
                ))
                continue
            if deformation is not None:
                raise doc.error("a skinned or morphed mesh cannot be instanced here (its pose is per vertex)",
                                f"nodes[{i}].extensions.{INSTANCING}")
            if len(copies) * int(keep.sum()) > MAX_ELEMENTS:  # each triangle is an element at least
                raise doc.error(f"{len(copies):,} copies of {int(keep.sum()):,} triangles exceed the "
                                f"{MAX_ELEMENTS:,} elements a scene may have", f"nodes[{i}].extensions.{INSTANCING}")
            for k, transform in enumerate(copies):
                placed, placed_faces, normals = place_copy(verts, faces[keep], attributes.normals, transform)
                instances.append(MeshInstance(
                    index=len(instances), node=i, mesh=node.mesh, primitive=p, name=f"{name}#{k}",
                    vertices=placed, faces=placed_faces, material=material, source_faces=source[keep],
                    attributes=None if attributes.empty else replace(attributes, normals=normals),
                ))
    return instances, dropped


def _read_skins(doc, order) -> list[Skin]:
    """The file's skins (glTF 2.0 §3.7.3): joints that are nodes of the rendered scene, and their
    inverse bind matrices (MAT4 floats, column-major; identity when absent)."""
    g = doc.gltf
    reachable = set(order)
    skins = []
    for s, raw in enumerate(g.skins):
        f = f"skins[{s}]"
        joints = list(raw.joints or [])
        if not joints:
            raise doc.error("has no joints", f + ".joints")
        for j in joints:
            if not 0 <= j < len(g.nodes):
                raise doc.error(f"joint {j} is not a node", f + ".joints")
        if len(set(joints)) != len(joints):
            raise doc.error("lists a joint twice", f + ".joints")
        if raw.inverseBindMatrices is None:
            ibm = np.tile(np.eye(4), (len(joints), 1, 1))
        else:
            data = np.asarray(doc.accessor(raw.inverseBindMatrices, f + ".inverseBindMatrices", types=("MAT4",),
                                           components=(5126,)), dtype=np.float64)
            if len(data) < len(joints):
                raise doc.error(f"has {len(data)} matrices for {len(joints)} joints", f + ".inverseBindMatrices")
            if not np.all(np.isfinite(data)):
                raise doc.error("holds NaN or Inf", f + ".inverseBindMatrices")
            ibm = data[:len(joints)].reshape(-1, 4, 4).transpose(0, 2, 1)  # column-major
        skins.append(Skin(s, tuple(int(j) for j in joints), ibm))
    used = {n.skin for n in (g.nodes[i] for i in order) if n.skin is not None and n.mesh is not None}
    for s in sorted(used):
        if not 0 <= s < len(skins):
            continue  # the node's own check names it
        outside = [j for j in skins[s].joints if j not in reachable]
        if outside:
            raise doc.error(f"joint node {outside[0]} is not in the rendered scene", f"skins[{s}].joints")
    return skins


def _read_deformation(doc, node: int, mesh: int, prim, f: str, n_vertices: int,
                      skin: Skin | None, warnings: list[str]) -> Deformation | None:
    """The skin binding (JOINTS_n/WEIGHTS_n, every set) and morph targets of one primitive, checked;
    None when the primitive is rigid."""
    g = doc.gltf

    def vec3(index, where):
        data = np.asarray(doc.accessor(index, where, types=("VEC3",)), dtype=np.float64)
        if len(data) != n_vertices:
            raise doc.error(f"has {len(data)} entries for {n_vertices} positions", where)
        if not np.all(np.isfinite(data)):
            raise doc.error(f"entry {int(np.flatnonzero(~np.isfinite(data).all(1))[0])} is NaN or Inf", where)
        return data

    targets = [t if isinstance(t, dict) else vars(t) for t in (prim.targets or [])]
    counts = {len(q.targets or []) for q in g.meshes[mesh].primitives}
    if len(counts) > 1:  # glTF 2.0 §3.7.2.2: all primitives have the same number of targets
        raise doc.error(f"its primitives have different numbers of morph targets ({sorted(counts)})",
                        f"meshes[{mesh}].primitives")
    positions = normals = tangents = weights0 = None
    if targets:
        k = len(targets)
        positions, normals, tangents = (np.zeros((k, n_vertices, 3)) for _ in range(3))
        has_p = has_n = has_t = False
        for t, target in enumerate(targets):
            if target.get("POSITION") is not None:
                positions[t] = vec3(target["POSITION"], f"{f}.targets[{t}].POSITION")
                has_p = True
            if target.get("NORMAL") is not None:
                normals[t] = vec3(target["NORMAL"], f"{f}.targets[{t}].NORMAL")
                has_n = True
            if target.get("TANGENT") is not None:  # xyz displacements (glTF 2.0 §3.7.2.2)
                tangents[t] = vec3(target["TANGENT"], f"{f}.targets[{t}].TANGENT")
                has_t = True
        positions, normals = (positions if has_p else None), (normals if has_n else None)
        tangents = tangents if has_t else None
        weights0, where = np.zeros(k), None
        node_weights = doc.tree.get("nodes", [{}] * len(g.nodes))[node].get("weights")  # not in pygltflib
        if node_weights is not None:
            weights0, where = node_weights, f"nodes[{node}].weights"
        elif doc.tree.get("meshes", [{}] * len(g.meshes))[mesh].get("weights") is not None:
            weights0, where = doc.tree["meshes"][mesh]["weights"], f"meshes[{mesh}].weights"
        weights0 = np.asarray(weights0, dtype=np.float64)
        if len(weights0) != k:
            raise doc.error(f"has {len(weights0)} weights for the {k} morph targets of {f}", where)

    joints = weights = None
    if skin is not None:
        sets = []
        n = 0
        while getattr(prim.attributes, f"JOINTS_{n}", None) is not None:
            jw, ww = f"{f}.attributes.JOINTS_{n}", f"{f}.attributes.WEIGHTS_{n}"
            if getattr(prim.attributes, f"WEIGHTS_{n}", None) is None:
                raise doc.error(f"JOINTS_{n} has no WEIGHTS_{n}", f + ".attributes")
            j = np.asarray(doc.accessor(getattr(prim.attributes, f"JOINTS_{n}"), jw, types=("VEC4",),
                                        components=_JOINT_COMPONENTS), dtype=np.int64)
            w = np.asarray(doc.accessor(getattr(prim.attributes, f"WEIGHTS_{n}"), ww, types=("VEC4",),
                                        components=_WEIGHT_COMPONENTS), dtype=np.float64)
            for data, where in ((j, jw), (w, ww)):
                if len(data) != n_vertices:
                    raise doc.error(f"has {len(data)} entries for {n_vertices} positions", where)
            if j.max(initial=0) >= len(skin.joints):
                raise doc.error(f"joint {int(j.max())} is out of range for the {len(skin.joints)} joints of "
                                f"skins[{skin.index}]", jw)
            if not np.all(np.isfinite(w)) or w.min(initial=0.0) < 0:
                raise doc.error("weights must be finite and non-negative", ww)
            sets.append((j, w))
            n += 1
        if not sets:
            raise doc.error(f"the node has skins[{skin.index}] but the primitive has no JOINTS_0/WEIGHTS_0",
                            f + ".attributes")
        joints = np.concatenate([j for j, _ in sets], axis=1)
        raw = np.concatenate([w for _, w in sets], axis=1)
        unbound = int((raw.sum(axis=1) <= 0).sum())
        if unbound:  # exporters leave unweighted vertices so; a renderer that skins them collapses them
            warnings.append(f"{f}: {unbound} vertex(es) have all skin weights zero: they follow the node "
                            f"{_node_name(doc, node)!r} unskinned")
        weights = normalise_weights(raw)
    if skin is None and positions is None and normals is None and tangents is None:
        return None
    return Deformation(target_positions=positions, target_normals=normals, target_tangents=tangents,
                       default_weights=weights0,
                       skin=skin, joints=joints, weights=weights)


def _node_name(doc, node: int) -> str:
    return doc.gltf.nodes[node].name or f"node{node}"


def _with_textures(doc: GltfDocument, materials: list) -> list:
    """Materials with their base-colour, emissive, normal, metallic-roughness and transmission textures
    attached, each image decoded once (per colour encoding)."""
    images: dict = {}
    return [replace(m, base_color_texture=base_color_texture(doc, i, images),
                    emissive_texture=emissive_texture(doc, i, images), normal_texture=normal_texture(doc, i, images),
                    metallic_roughness_texture=metallic_roughness_texture(doc, i, images),
                    transmission_texture=transmission_texture(doc, i, images))
            for i, m in enumerate(materials)]


def _texcoord_warnings(materials, instances, warnings) -> None:
    """Warn where a textured material meets a primitive without the texture coordinates it samples."""
    for inst in instances:
        mat = materials[inst.material]
        have = inst.attributes.texcoords if inst.attributes is not None else {}
        for tex in (mat.base_color_texture, mat.emissive_texture):
            if tex is not None and tex.texcoord not in have:
                warnings.append(f"{inst.name}: material {mat.name!r} samples TEXCOORD_{tex.texcoord}, "
                                "which the primitive lacks: its texture is read at (0, 0)")
                break


def _read_channels(doc, nodes, warnings, first: str | None
                   ) -> tuple[dict[tuple, Sampler], list[str], list[str], list[str]]:
    """The channels that play ((kind, index, property) -> sampler, the kinds of _read_animation); the
    names of the animations that play, of those left out, and of those that would play by default.

    glTF says nothing of how animations combine. Files put things that move together in one
    animation or in several over different nodes (ROOM's flight and torus), which all play; a
    character's clips (Fox's Survey, Walk and Run) animate the same nodes and are alternatives,
    played one at a time, by default the first, as viewers such as <model-viewer> do. So the
    animations play in file order, each unless it animates a node and path an earlier one that
    plays already does; every animation is checked all the same. ``first`` (--animation) names
    the animation that plays first, the others following in file order by the same rule."""
    unsupported: set[str] = set()
    clips = [(_animation_name(anim, a), _read_animation(doc, nodes, warnings, a, anim, unsupported))
             for a, anim in enumerate(doc.gltf.animations)]
    if unsupported and POINTER in (doc.gltf.extensionsRequired or ()):
        raise doc.error(f"requires {POINTER} for {', '.join(sorted(unsupported))}, which photonloom does not "
                        f"animate (it animates {ANIMATED_POINTERS})", "extensionsRequired")
    if unsupported:
        warnings.append(f"{POINTER} targets not animated, kept at the file's values: "
                        f"{', '.join(sorted(unsupported))} (animated are {ANIMATED_POINTERS})")
    default = _play(clips)[1]
    if first is not None:
        names = [name for name, _ in clips]
        if first not in names:
            raise doc.error(f"no animation is named {first!r} (the file has "
                            f"{', '.join(map(repr, names)) if names else 'none'})", "animations")
        clips.sort(key=lambda clip: clip[0] != first)  # stable: the others keep the file's order
    channels, played, left_out = _play(clips)
    return channels, played, left_out, default


def _play(clips: list) -> tuple[dict[tuple, Sampler], list[str], list[str]]:
    """Channels (target -> sampler), names played and names left out of (name, samplers) ``clips``
    taken in order."""
    channels: dict[tuple, Sampler] = {}
    played, left_out = [], []
    for name, samplers in clips:
        if any(key in channels for key in samplers):
            left_out.append(name)
            continue
        played.append(name)
        channels.update(samplers)
    return channels, played, left_out


def _by_target(channels: dict[tuple, Sampler], kind: str) -> dict[int, dict[str, Sampler]]:
    """index -> property -> sampler of the channels whose target is a ``kind`` (node, light, material
    or camera)."""
    out: dict[int, dict[str, Sampler]] = {}
    for (what, index, prop), sampler in channels.items():
        if what == kind:
            out.setdefault(index, {})[prop] = sampler
    return out


def _animation_name(anim, index: int) -> str:
    return anim.name if isinstance(anim.name, str) and anim.name else f"animation {index}"


def _read_animation(doc, nodes, warnings, a: int, anim, unsupported: set[str]) -> dict[tuple, Sampler]:
    """One animation's channels, checked: (kind, index, property) -> sampler, the kind "node" for
    core targets and the kinds of :func:`_pointer_target` for KHR_animation_pointer's; other
    pointers are skipped and their patterns added to ``unsupported``."""
    g = doc.gltf
    samplers: dict[tuple, Sampler] = {}
    for c, ch in enumerate(anim.channels):
        f = f"animations[{a}].channels[{c}]"
        target = ch.target
        if target is not None and target.path == "pointer":
            key = pointer_target(doc, target, f, unsupported)
            if key is None:
                continue
        elif target is None or target.path not in PATHS + ("weights",):
            raise doc.error(f"target path {getattr(target, 'path', None)!r} is not supported", f + ".target.path")
        elif target.node is None:  # allowed by the spec (extensions may target other things)
            continue
        else:
            key = ("node", target.node, target.path)
        kind, index, prop = key
        if kind in ("node", "visibility") and not 0 <= index < len(nodes):
            raise doc.error(f"targets missing node {index}", f + ".target.node" if kind == "node" else
                            f + ".target.extensions.KHR_animation_pointer.pointer")
        n_targets = None
        if kind == "node" and prop == "weights":  # one value per morph target of the node's mesh (§3.11)
            mesh = nodes[index].mesh
            n_targets = len(g.meshes[mesh].primitives[0].targets or []) if mesh is not None else 0
            if not n_targets:
                warnings.append(f"{f}: animates the morph weights of node {index}, whose mesh has no "
                                "morph targets: ignored")
                continue
        elif kind == "node" and nodes[index].matrix is not None:
            raise doc.error("targets a node defined by a matrix (glTF requires TRS)", f + ".target.node")
        if ch.sampler is None or not 0 <= ch.sampler < len(anim.samplers):
            raise doc.error(f"refers to missing sampler {ch.sampler}", f + ".sampler")
        s = anim.samplers[ch.sampler]
        sf = f"animations[{a}].samplers[{ch.sampler}]"
        interp = s.interpolation or "LINEAR"
        if interp not in INTERPOLATIONS:
            raise doc.error(f"interpolation {interp!r} is not one of {', '.join(INTERPOLATIONS)}", sf)
        if kind == "visibility" and interp != "STEP":  # a boolean (KHR_animation_pointer)
            raise doc.error(f"interpolation {interp} cannot animate a boolean (visible): it must be STEP", sf)
        times = np.asarray(doc.accessor(s.input, sf + ".input", types=("SCALAR",), components=(5126,)),
                           dtype=np.float64).ravel()
        restrict = BOOLEAN_ACCESSOR if kind == "visibility" else {}
        values = np.asarray(doc.accessor(s.output, sf + ".output", **restrict), dtype=np.float64)
        width = WIDTHS.get(prop, 0)  # weights: n_targets, below
        if width == 1 and values.ndim == 1:  # a scalar property: SCALAR keys
            values = values.reshape(-1, 1)
        if n_targets is not None:  # scalars, n_targets per key (x 3 for CUBICSPLINE)
            width = n_targets
            if values.ndim != 1 or len(values) % n_targets:
                raise doc.error(f"output must be scalars, {n_targets} per key (the node's morph targets), "
                                f"got {len(values)}", sf + ".output")
            values = values.reshape(-1, n_targets)
        if values.ndim != 2 or values.shape[1] != width:
            raise doc.error(f"output must be {'scalars' if width == 1 else f'{width}-vectors'} for {prop}",
                            sf + ".output")
        if not (np.all(np.isfinite(times)) and np.all(np.isfinite(values))):
            raise doc.error("keyframes contain NaN or Inf", sf)
        if np.any(np.diff(times) <= 0):
            raise doc.error("input times must increase strictly", sf + ".input")
        per_key = 3 if interp == "CUBICSPLINE" else 1
        if len(values) != per_key * len(times):
            raise doc.error(f"has {len(values)} outputs for {len(times)} keys ({interp})", sf + ".output")
        if interp == "CUBICSPLINE":
            values = values.reshape(len(times), 3, width)
        keys = values[:, 1] if interp == "CUBICSPLINE" else values  # not the cubic tangents
        if kind in ("light", "material") and prop in NON_NEGATIVE_PROPERTIES and np.any(keys < 0):
            raise doc.error(f"{kind} {prop} keys must not be negative", sf + ".output")
        if kind == "camera" and prop == "yfov" and not np.all((keys > 0) & (keys < np.pi)):
            raise doc.error("camera yfov keys must lie in (0, pi)", sf + ".output")
        if kind == "camera" and prop == "ymag" and not np.all(keys != 0):
            raise doc.error("camera ymag keys must not be zero", sf + ".output")
        if prop == "rotation":  # keys must be rotations
            bad = np.flatnonzero(np.linalg.norm(keys, axis=1) <= 1e-6)
            if len(bad):
                raise doc.error(f"rotation key {int(bad[0])} is a zero quaternion", sf + ".output")
        samplers[key] = Sampler(times, values, interp, prop)
    return samplers


def _scene_extras(doc: GltfDocument) -> dict:
    g = doc.gltf
    extras = {}
    if g.scenes:
        idx = g.scene if g.scene is not None else 0
        extras = (g.scenes[idx].extras or {}) if isinstance(g.scenes[idx].extras, dict) else {}
    ours = extras.get("photonloom", {})
    return ours if isinstance(ours, dict) else {}


def _choose_camera(doc, nodes, order, cameras, name):
    """The camera node to render from; None for the auto camera (``name`` auto, or no camera)."""
    candidates = [i for i in order if nodes[i].camera is not None and cameras[nodes[i].camera] is not None]
    if name is None:
        return candidates[0] if candidates else None
    if name == AUTO:
        return None
    for i in candidates:
        if name in (nodes[i].name, cameras[nodes[i].camera].name):
            return i
    names = ", ".join(sorted({cameras[nodes[i].camera].name for i in candidates} | {AUTO}))
    raise doc.error(f"no camera named {name!r} (cameras: {names})", "cameras")
