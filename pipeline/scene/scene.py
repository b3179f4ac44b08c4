"""An animated glTF 2.0 scene and its pose at any instant.

:class:`Scene` holds what the file defines (node hierarchy, mesh instances in rest coordinates,
materials, lights, cameras, animation channels, timeline). :meth:`Scene.pose` evaluates the
animation at a time and returns a :class:`FrameState` with world-space triangles, lights and camera.
Nothing stores positions per frame: poses are computed on demand.

A *mesh instance* is one primitive of a mesh placed by one node; its triangles keep their order
from the file, less the zero-area ones (dropped and counted). Global source-triangle indices run
over all instances in depth-first node order; the element mesh and the photon tracer share them.
"""
from __future__ import annotations

import hashlib
import logging
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path

import numpy as np

from .animation import Sampler, joint_matrices, pose_tangents, pose_vertices, trs_matrix
from .camera import AUTO, Camera, CameraDef, Framing
from .environment import EnvironmentMap
from .gltf import GltfDocument
from .lights import Light, LightDef
from .materials import Material, animated_material, any_emits, may_reflect
from .nodes import MeshInstance, Node
from .shading import CornerAttributes, corner_attributes, world_corner_normals, world_corner_tangents
from .sky import Sky
from .timeline import Timeline
from .visibility import visible_nodes

log = logging.getLogger(__name__)

# State keys compare poses rounded to this many decimals, so that float noise from slerp of equal
# keys does not make two identical poses look different.
_STATE_DECIMALS = 7
# Default element size for files that do not state one: this fraction of the bounding-box diagonal.
DEFAULT_ELEMENT_FRACTION = 1.0 / 50.0


@dataclass
class FrameState:
    """The scene at one instant, in world space: what the tracer and compositor need."""

    time: float
    frame: int | None
    vertices: np.ndarray  # (V, 3) float32, all instances concatenated
    faces: np.ndarray  # (F, 3) int32 into vertices, global source-triangle order
    triangle_instance: np.ndarray  # (F,) int32
    triangle_material: np.ndarray  # (F,) int32 into materials
    materials: list[Material]
    lights: list[Light]
    emissive_triangles: np.ndarray  # (E,) int32 global triangle indices with emissive material
    camera: Camera | None
    instance_matrices: np.ndarray  # (I, 4, 4) float64 local-to-world of each instance
    state_key: str  # equal for two instants whose geometry and lights are equal
    corner_normals: np.ndarray | None = None  # (F, 3, 3) float32 world vertex normals (shading.py)
    corner_tangents: np.ndarray | None = None  # (F, 3, 4) float32 world TANGENTs, w the handedness (shading.py)
    corners: CornerAttributes | None = None  # texture coordinates and colours per corner (shading.py)
    sky: Sky | EnvironmentMap | None = None  # the sky at infinity (sky.py, environment.py), if the scene has one
    # Instances posed per vertex (skins, morph targets): their world vertices are in ``vertices``,
    # ``instance_matrices`` does not place them (ElementMesh.vertex_positions reads them from there)
    deformed_instances: tuple[int, ...] = ()
    # Instances whose world transform mirrors them (negative determinant; a skin's joints excepted):
    # glTF reverses their winding (§3.7.2.1), so their front faces are the other side of their corners' order
    mirrored_instances: tuple[int, ...] = ()

    def front_sign(self) -> np.ndarray:
        """(F,) +1, or -1 where a triangle's corner order gives its back (a mirrored instance)."""
        sign = np.ones(len(self.instance_matrices))
        sign[list(self.mirrored_instances)] = -1.0
        return sign[self.triangle_instance]


@dataclass
class Scene:
    path: Path
    document: GltfDocument = field(repr=False)
    nodes: list[Node]
    order: list[int]  # reachable nodes, parents before children (depth first)
    instances: list[MeshInstance]
    materials: list[Material]
    light_defs: list[LightDef]
    cameras: list[CameraDef]
    channels: dict[int, dict[str, Sampler]]  # node -> translation | rotation | scale | weights -> sampler
    timeline: Timeline
    camera_node: int | None
    element_size: float
    dropped_triangles: int
    warnings: list[str]
    # What the loader chose for a file that lacks it (pipeline/scene/loader.py), one line each
    notices: list[str] = field(default_factory=list)
    default_lights: tuple[Light, ...] = ()  # pipeline/scene/default_lights.py: the file has no light
    sky: Sky | EnvironmentMap | None = None
    framing: Framing | None = None  # the auto camera (pipeline/scene/default_camera.py), no camera_node
    # KHR_animation_pointer's channels (pipeline/scene/pointers.py): light -> intensity | color | range |
    # innerConeAngle | outerConeAngle; material -> the short names of materials.ANIMATED_PROPERTIES;
    # camera -> yfov
    light_channels: dict[int, dict[str, Sampler]] = field(default_factory=dict)
    material_channels: dict[int, dict[str, Sampler]] = field(default_factory=dict)
    camera_channels: dict[int, dict[str, Sampler]] = field(default_factory=dict)
    # node -> its animated KHR_node_visibility ``visible`` (pipeline/scene/visibility.py)
    visibility_channels: dict[int, Sampler] = field(default_factory=dict)
    # Nodes hidden at every instant (KHR_node_visibility): their meshes are not loaded, their lights never shine
    hidden_nodes: frozenset[int] = frozenset()
    # The animations that play and those left out, alternative clips of nodes one that plays animates
    # (pipeline/scene/loader.py); the --animation that chose them, None where they are the default
    animations_played: tuple[str, ...] = ()
    animations_left_out: tuple[str, ...] = ()
    animation_option: str | None = None
    variant_option: str | None = None  # the KHR_materials_variants variant rendered (pipeline/scene/variants.py)

    # --- identity ---------------------------------------------------------------------------------

    @property
    def scene_hash(self) -> str:
        """Digest of the file's JSON and buffers, and of the animations that play where they are
        not the default ones: which scene a photon store was made from."""
        if self.animation_option is None:
            return self.document.digest[:16]
        chosen = "\0".join((self.document.digest, *self.animations_played))
        return hashlib.sha256(chosen.encode()).hexdigest()[:16]

    # --- animation --------------------------------------------------------------------------------

    def world_matrices(self, t: float) -> np.ndarray:
        """(n_nodes, 4, 4) local-to-world matrices at time ``t`` (unreachable nodes: identity)."""
        world = np.tile(np.eye(4), (len(self.nodes), 1, 1))
        for i in self.order:
            node = self.nodes[i]
            if node.matrix is not None:
                local = node.matrix
            else:
                ch = self.channels.get(i, {})
                tr = ch["translation"].evaluate(t) if "translation" in ch else node.translation
                rot = ch["rotation"].evaluate(t) if "rotation" in ch else node.rotation
                sc = ch["scale"].evaluate(t) if "scale" in ch else node.scale
                local = trs_matrix(tr, rot, sc)
            world[i] = local if node.parent is None else world[node.parent] @ local
        return world

    def light_def(self, light: int, t: float) -> LightDef:
        """Light ``light`` of the file at ``t``: its colour, intensity, range and spot cones as
        animated (KHR_animation_pointer), clamped at 0 where a cubic spline overshoots, the outer
        cone within (0, pi/2] and the inner one below it."""
        d, ch = self.light_defs[light], self.light_channels.get(light)
        if not ch:
            return d
        value = {name: s.evaluate(t) for name, s in ch.items()}
        color = tuple(float(c) for c in np.maximum(value["color"], 0.0)) if "color" in ch else d.color
        intensity = max(float(value["intensity"][0]), 0.0) if "intensity" in ch else d.intensity
        rng = max(float(value["range"][0]), 1e-9) if "range" in ch else d.range
        outer = float(np.clip(value["outerConeAngle"][0], 1e-6, np.pi / 2)) if "outerConeAngle" in ch else d.outer_cone
        inner = float(value["innerConeAngle"][0]) if "innerConeAngle" in ch else d.inner_cone
        return replace(d, color=color, intensity=intensity, range=rng, outer_cone=outer,
                       inner_cone=float(np.clip(inner, 0.0, outer * (1 - 1e-6))))

    @property
    def has_animation(self) -> bool:
        """Something in the file is animated: a node, its visibility, a light, a material or a camera's
        field of view."""
        return bool(self.channels or self.light_channels or self.material_channels or self.camera_channels
                    or self.visibility_channels)

    def materials_at(self, t: float) -> list[Material]:
        """The materials at ``t``, their animated properties (KHR_animation_pointer, pointers.py) applied."""
        if not self.material_channels:
            return self.materials
        mats = list(self.materials)
        for m, ch in self.material_channels.items():
            mats[m] = animated_material(mats[m], self.document.gltf.materials[m],
                                        {k: s.evaluate(t) for k, s in ch.items()})
        return mats

    def visible_nodes(self, t: float) -> np.ndarray:
        """(n_nodes,) bool: the nodes shown at ``t`` (KHR_node_visibility, pipeline/scene/visibility.py)."""
        return visible_nodes(self.nodes, self.order, self.visibility_channels, t)

    def _lights_at(self, world: np.ndarray, t: float, shown: np.ndarray) -> list[Light]:
        lights = []
        for i in self.order:
            node = self.nodes[i]
            if node.light is None or not shown[i]:
                continue
            m = world[i]
            d = -m[:3, 2]
            norm = np.linalg.norm(d)
            lights.append(Light(self.light_def(node.light, t), i, m[:3, 3].copy(),
                                d / norm if norm > 0 else np.array([0.0, 0.0, -1.0])))
        return lights + list(self.default_lights)

    def morph_weights(self, inst: MeshInstance, t: float) -> np.ndarray | None:
        """(K,) morph weights of a deforming instance at ``t``: its node's animated ``weights``,
        else the node's or mesh's default weights (glTF 2.0 §3.7.2.2); None without targets."""
        d = inst.deformation
        if d is None or not d.n_targets:
            return None
        sampler = self.channels.get(inst.node, {}).get("weights")
        return d.default_weights if sampler is None else sampler.evaluate(t)

    def _joint_world(self, inst: MeshInstance, world: np.ndarray) -> np.ndarray | None:
        d = inst.deformation
        return None if d is None or d.skin is None else world[list(d.skin.joints)]

    def deformed_vertices(self, inst: MeshInstance, world: np.ndarray, t: float, *, normals: bool = True
                          ) -> tuple[np.ndarray, np.ndarray | None]:
        """World positions (V, 3) and unit normals (None without NORMAL, or when ``normals`` is
        False) of a deforming instance at ``t``, ``world`` being :meth:`world_matrices` (animation.py)."""
        a = inst.attributes
        base_normals = a.normals if a is not None and normals else None
        return pose_vertices(inst.vertices, base_normals, inst.deformation,
                             self.morph_weights(inst, t), world[inst.node], self._joint_world(inst, world))

    @property
    def deforming(self) -> list[MeshInstance]:
        """Instances with a skin or morph targets, posed per vertex."""
        return [inst for inst in self.instances if inst.deformation is not None]

    def _state_key(self, world: np.ndarray, lights: list[Light], materials: list[Material], t: float,
                   shown: np.ndarray) -> str:
        h = hashlib.sha256(self.document.digest.encode())  # keys of different scenes never collide
        if self.visibility_channels:  # a mesh shown or hidden is geometry too
            h.update(np.packbits(shown).tobytes())
        for inst in self.instances:
            h.update(np.round(world[inst.node], _STATE_DECIMALS).tobytes())
            if inst.deformation is not None:  # a skin's or a morph's pose is geometry too
                weights = self.morph_weights(inst, t)
                if weights is not None:
                    h.update(np.round(weights, _STATE_DECIMALS).tobytes())
                joints = self._joint_world(inst, world)
                if joints is not None:
                    h.update(np.round(joint_matrices(joints, inst.deformation.skin.inverse_bind),
                                      _STATE_DECIMALS).tobytes())
        for light in lights:
            h.update(np.round(light.state(), _STATE_DECIMALS).tobytes())
            if light.node >= 0 and self.nodes[light.node].light in self.light_channels:  # animated cones, range
                d = light.definition
                h.update(np.round([d.inner_cone, d.outer_cone, d.range or 0.0], _STATE_DECIMALS).tobytes())
        for m in sorted(self.material_channels):  # animated materials change what photons carry and what emits
            h.update(np.round(materials[m].state(), _STATE_DECIMALS).tobytes())
        if self.sky is not None:
            h.update(np.round(self.sky.state(), _STATE_DECIMALS).tobytes())
        return h.hexdigest()[:16]

    def state_key(self, frame: int) -> str:
        """Key equal for frames whose geometry and lights are equal (camera-only motion)."""
        t = self.timeline.time(frame)
        world = self.world_matrices(t)
        shown = self.visible_nodes(t)
        return self._state_key(world, self._lights_at(world, t, shown), self.materials_at(t), t, shown)

    def pose(self, t: float, *, frame: int | None = None, every_node: bool = False) -> FrameState:
        """Evaluate the animation at ``t`` seconds: world-space triangles, lights and camera. A
        hidden node's meshes collapse to its origin (zero area: no ray meets them) and its lights go
        out, unless ``every_node`` (the element mesh splits every triangle as it stands)."""
        world = self.world_matrices(t)
        shown = np.ones(len(self.nodes), bool) if every_node else self.visible_nodes(t)
        lights = self._lights_at(world, t, shown)
        inst_mats = np.stack([world[inst.node] for inst in self.instances])
        verts = [(inst.vertices @ m[:3, :3].T + m[:3, 3]) for inst, m in zip(self.instances, inst_mats)]
        corner_normals = world_corner_normals(self.instances, inst_mats)
        corner_tangents = world_corner_tangents(self.instances, inst_mats)
        first_face = np.cumsum([0] + [len(inst.faces) for inst in self.instances])
        for inst in self.deforming:
            verts[inst.index], normals = self.deformed_vertices(inst, world, t)
            faces_of = slice(first_face[inst.index], first_face[inst.index + 1])
            if normals is not None and corner_normals is not None:
                corner_normals[faces_of] = normals[inst.faces]
            if inst.attributes is not None and inst.attributes.tangents is not None:
                corner_tangents[faces_of] = pose_tangents(inst.attributes.tangents, inst.deformation,
                                                          self.morph_weights(inst, t), world[inst.node],
                                                          self._joint_world(inst, world))[inst.faces]
        for inst in self.instances:
            if not shown[inst.node]:
                verts[inst.index] = np.broadcast_to(world[inst.node][:3, 3], verts[inst.index].shape)
        offsets = np.cumsum([0] + [len(v) for v in verts])
        faces = np.concatenate([inst.faces + off for inst, off in zip(self.instances, offsets)])
        tri_inst = np.concatenate(
            [np.full(len(inst.faces), inst.index, np.int32) for inst in self.instances]
        )
        tri_mat = np.asarray([inst.material for inst in self.instances], np.int32)[tri_inst]
        materials = self.materials_at(t)
        emissive_mats = np.array([m.is_emissive for m in materials])
        cam = None
        if self.camera_node is not None:
            node = self.nodes[self.camera_node]
            defn, ch = self.cameras[node.camera], self.camera_channels.get(node.camera)
            if ch and "yfov" in ch:  # a zoom (KHR_animation_pointer): the field of view at t, kept inside (0, pi)
                defn = replace(defn, yfov=float(np.clip(ch["yfov"].evaluate(t)[0], 1e-6, np.pi - 1e-6)))
            if ch and "ymag" in ch and defn.orthographic:  # an orthographic zoom: the view's half height
                defn = replace(defn, ymag=max(abs(float(ch["ymag"].evaluate(t)[0])), 1e-9))
            cam = Camera(defn, self.camera_node, world[self.camera_node].copy())
        elif self.framing is not None:
            cam = self.framing.camera
        with np.errstate(over="ignore"):  # beyond float32 becomes Inf, which ElementMesh.build refuses
            vertices = np.concatenate(verts).astype(np.float32)
        return FrameState(
            time=float(t),
            frame=frame,
            vertices=vertices,
            faces=faces.astype(np.int32),
            triangle_instance=tri_inst,
            triangle_material=tri_mat,
            materials=materials,
            lights=lights,
            emissive_triangles=np.flatnonzero(emissive_mats[tri_mat]).astype(np.int32),
            camera=cam,
            instance_matrices=inst_mats,
            state_key=self._state_key(world, lights, materials, t, shown),
            corner_normals=corner_normals,
            corner_tangents=corner_tangents,
            corners=self.corner_attributes,
            sky=self.sky,
            deformed_instances=tuple(inst.index for inst in self.deforming),
            mirrored_instances=tuple(inst.index for inst, m in zip(self.instances, inst_mats)
                                     if np.linalg.det(m[:3, :3]) < 0
                                     and (inst.deformation is None or inst.deformation.skin is None)),
        )

    def pose_frame(self, frame: int, *, every_node: bool = False) -> FrameState:
        """:meth:`pose` at a frame number of the timeline."""
        return self.pose(self.timeline.time(frame), frame=frame, every_node=every_node)

    # --- summaries ------------------------------------------------------------------------------

    @property
    def camera_name(self) -> str | None:
        """The rendering camera's node name, ``auto`` for the auto camera, None without a camera."""
        if self.camera_node is not None:
            return self.nodes[self.camera_node].name
        return AUTO if self.framing is not None else None

    @property
    def n_triangles(self) -> int:
        return sum(len(inst.faces) for inst in self.instances)

    @cached_property
    def corner_attributes(self) -> CornerAttributes | None:
        """Texture coordinates and vertex colours of every triangle corner (they do not move)."""
        return corner_attributes(self.instances)

    @property
    def animated_nodes(self) -> list[int]:
        """Nodes whose transform, morph weights or visibility is animated."""
        return sorted(set(self.channels) | set(self.visibility_channels))

    @cached_property
    def frame_state_keys(self) -> list[str]:
        """State key of every frame of the timeline, in order."""
        return [self.state_key(f) for f in self.timeline.all_frames()]

    @property
    def has_moving_geometry(self) -> bool:
        """True when geometry or lights change over the timeline (photons must be re-traced)."""
        return len(set(self.frame_state_keys)) > 1

    @property
    def has_camera_motion(self) -> bool:
        if self.camera_node is None:
            return False
        if self.nodes[self.camera_node].camera in self.camera_channels:  # a zoom
            return True
        node = self.camera_node
        moving = {n for n, ch in self.channels.items() if set(ch) - {"weights"}}  # morph weights move no node
        while node is not None:
            if node in moving:
                return True
            node = self.nodes[node].parent
        return False

    @property
    def has_specular(self) -> bool:
        """Some surface is a mirror or glossy at some instant (reflection rays are needed)."""
        gltf_materials = self.document.gltf.materials
        return any(may_reflect(self.materials[m], gltf_materials[m], self.material_channels.get(m))
                   if m < len(gltf_materials) else self.materials[m].is_specular
                   for m in {inst.material for inst in self.instances})

    @property
    def has_area_lights(self) -> bool:
        return any_emits(self.materials, self.document.gltf.materials, self.material_channels,
                         {inst.material for inst in self.instances})
