"""What ``loom info`` prints: a plain-text summary of a scene and of the work it needs."""
from __future__ import annotations

from collections import Counter

import numpy as np

from .elements import ElementMesh
from .scene import Scene

INFO_STATE_FRAMES = 2_000


def describe(scene: Scene, element_size: float | None = None) -> list[str]:
    """Lines describing timeline, geometry, lights, materials, cameras, animation and needs."""
    tl = scene.timeline
    elements = ElementMesh.build(scene, element_size)
    used = sorted({inst.material for inst in scene.instances})
    kinds = Counter()
    for m in used:
        mat = scene.materials[m]
        kinds["emissive" if mat.is_emissive else ("specular" if mat.is_specular else "diffuse")] += 1
    light_kinds = Counter(scene.light_defs[scene.nodes[i].light].kind
                          for i in scene.order if scene.nodes[i].light is not None)
    n_area = sum(len(i.faces) for i in scene.instances if scene.materials[i.material].is_emissive)
    cams = [f"{scene.cameras[scene.nodes[i].camera].name} (node {scene.nodes[i].name})"
            for i in scene.order if scene.nodes[i].camera is not None and scene.cameras[scene.nodes[i].camera]]
    chosen = scene.nodes[scene.camera_node].name if scene.camera_node is not None else "none"
    animated = [f"{scene.nodes[i].name} [{', '.join(sorted(scene.channels[i]))}]" for i in scene.animated_nodes]
    meshes = {inst.mesh for inst in scene.instances}
    # Scene states of at most INFO_STATE_FRAMES evenly spread frames: `loom info` does not pose
    # every frame of a long timeline (a render does, in pipeline/shoot.py's plan)
    sampled = sorted({round(x) for x in np.linspace(tl.first, tl.last, min(tl.frames, INFO_STATE_FRAMES))})
    distinct = len({scene.state_key(f) for f in sampled})
    if distinct > 1:
        motion = "moving geometry or lights (photons traced per frame)"
        motion += f", {distinct} distinct scene states" + (
            f" in {len(sampled):,} sampled frames" if len(sampled) < tl.frames else "")
    elif scene.has_camera_motion:
        motion = "camera-only motion (one photon set serves every frame)"
    else:
        motion = "static"
    lines = [
        f"scene      {scene.path}  (hash {scene.scene_hash})",
        f"frames     {tl.frames} at {tl.fps:g} fps, {tl.duration:.3f} s (frames {tl.first}-{tl.last})",
        f"meshes     {len(meshes)} meshes, {len(scene.instances)} instances, {scene.n_triangles} triangles"
        + (f" ({scene.dropped_triangles} zero-area dropped)" if scene.dropped_triangles else ""),
        f"elements   {elements.n_elements} elements, {elements.n_vertices} vertices "
        f"at element size {elements.element_size:g}",
        "lights     " + (", ".join(f"{n} {k}" for k, n in sorted(light_kinds.items())) or "no punctual lights")
        + (f"; {n_area} emissive triangles" if n_area else ""),
        "materials  " + ", ".join(f"{kinds[k]} {k}" for k in ("diffuse", "specular", "emissive")),
        f"cameras    {len(cams)}: " + (", ".join(cams) or "none") + f"; rendering with {chosen}",
        f"animated   {len(animated)} nodes" + (": " + ", ".join(animated) if animated else ""),
        "needs      " + "; ".join([
            motion,
            "specular surfaces (reflection rays)" if scene.has_specular else "no specular surfaces",
            "area lights (emissive triangles)" if scene.has_area_lights else "no area lights",
        ]),
    ]
    lines += [f"warning    {w}" for w in scene.warnings]
    return lines
