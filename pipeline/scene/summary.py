"""What ``loom info`` prints: a plain-text summary of a scene and of the work it needs."""
from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np

from .default_camera import describe_framing
from .default_lights import describe_default_lights
from .elements import ElementMesh
from .environment import EnvironmentMap
from .ignored import ignored
from .scene import Scene
from .variants import variant_names

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
                          for i in scene.order if scene.nodes[i].light is not None and i not in scene.hidden_nodes)
    hidden = sum(1 for i in scene.hidden_nodes if scene.nodes[i].mesh is not None or scene.nodes[i].light is not None)
    n_area = sum(len(i.faces) for i in scene.instances if scene.materials[i.material].is_emissive)
    cams = [f"{scene.cameras[scene.nodes[i].camera].name} (node {scene.nodes[i].name})"
            for i in scene.order if scene.nodes[i].camera is not None and scene.cameras[scene.nodes[i].camera]]
    chosen = scene.camera_name or "none"
    if scene.framing is not None:
        chosen = f"the {describe_framing(scene.framing)}"
    animated = [f"{scene.nodes[i].name} [{', '.join(sorted(scene.channels.get(i, {})) + visible)}]"
                for i in scene.animated_nodes for visible in [["visible"] if i in scene.visibility_channels else []]]
    others = []  # KHR_animation_pointer: lights, materials, cameras
    for label, names, channels in (("lights", [d.name for d in scene.light_defs], scene.light_channels),
                                   ("materials", [m.name for m in scene.materials], scene.material_channels),
                                   ("cameras", [c.name if c else "" for c in scene.cameras], scene.camera_channels)):
        if channels:
            others.append(f"; {len(channels)} {label}: " + ", ".join(
                f"{names[i]} [{', '.join(sorted(ch))}]" for i, ch in sorted(channels.items())))
    meshes = {inst.mesh for inst in scene.instances}
    # Scene states of at most INFO_STATE_FRAMES evenly spread frames: `loom info` does not pose
    # every frame of a long timeline (a render does, in pipeline/run/shoot.py's plan)
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
        + (f" ({scene.dropped_triangles} zero-area dropped)" if scene.dropped_triangles else "")
        + (f"; {hidden} node(s) with meshes or lights hidden throughout (KHR_node_visibility), left out"
           if hidden else ""),
        f"elements   {elements.n_elements} elements, {elements.n_vertices} vertices "
        f"at element size {elements.element_size:g}",
        "lights     " + (", ".join(f"{n} {k}" for k, n in sorted(light_kinds.items())) or "no punctual lights")
        + (f"; {n_area} emissive triangles" if n_area else "")
        + (f"; the file has none, rendering with the {describe_default_lights()}" if scene.default_lights else "")
        + _environment(scene),
        "materials  " + ", ".join(f"{kinds[k]} {k}" for k in ("diffuse", "specular", "emissive")),
        f"cameras    {len(cams)}: " + (", ".join(cams) or "none") + f"; rendering with {chosen}",
        f"animated   {len(animated)} nodes" + (": " + ", ".join(animated) if animated else "")
        + "".join(others),
        "needs      " + "; ".join([
            motion,
            "specular surfaces (reflection rays)" if scene.has_specular else "no specular surfaces",
            "area lights (emissive triangles)" if scene.has_area_lights else "no area lights",
        ]),
    ]
    names = variant_names(scene.document)
    if names:  # KHR_materials_variants
        lines.append(f"variants   {len(names)}: {', '.join(names)}; rendering "
                     + (f"{scene.variant_option!r}" if scene.variant_option else "each primitive's own material")
                     + " (--variant NAME)")
    lines.append("deforms    " + deforms_line(scene))
    lines += surface_lines(scene)
    lines += [f"warning    {w}" for w in scene.warnings]
    lines += [f"ignored    {w}" for w in ignored(scene)]
    return lines


def _environment(scene: Scene) -> str:
    """The lights line's account of an environment map, if the scene has one."""
    env = scene.sky
    if not isinstance(env, EnvironmentMap) or env.source is None:
        return ""
    turned = f", turned {env.rotation:g} deg" if env.rotation else ""
    return f"; an environment map around it, {Path(env.source[0]).name} ({env.size[1]}x{env.size[0]}, " \
           f"strength {env.source[1]:g}{turned})"


def deforms_line(scene: Scene) -> str:
    """What is posed per vertex: skinned and morphed primitives, their joints, targets and whether
    their pose changes over the timeline (pipeline/scene/animation.py)."""
    parts = []
    for inst in scene.deforming:
        d = inst.deformation
        what = []
        if d.skin is not None:
            animated = sum(1 for j in d.skin.joints if set(scene.channels.get(j, {})) - {"weights"})
            what.append(f"skin {d.skin.index} ({len(d.skin.joints)} joints, {animated} animated, up to "
                        f"{d.joints.shape[1]} influences)")
        if d.n_targets:
            driven = "weights" in scene.channels.get(inst.node, {})
            what.append(f"{d.n_targets} morph target(s), weights {'animated' if driven else 'fixed'}")
        parts.append(f"{inst.name}: " + ", ".join(what))
    if not parts:
        return "nothing (rigid meshes only)"
    return f"{len(parts)} of {len(scene.instances)} primitives posed per vertex: " + "; ".join(parts)




def surface_lines(scene: Scene) -> list[str]:
    """``textures``, ``normals`` and ``colours`` lines: what the file's surfaces carry and what is used."""
    used = sorted({inst.material for inst in scene.instances})
    textured = [scene.materials[m].base_color_texture for m in used
                if scene.materials[m].base_color_texture is not None]
    images = {t.image_index: t.image.shape for t in textured}
    if textured:
        sets = ", ".join(f"TEXCOORD_{s}" for s in sorted({t.texcoord for t in textured}))
        moved = sum(t.has_transform for t in textured)
        sizes = ", ".join(f"{w}x{h}" for h, w, _ in images.values())
        tex = (f"{len(images)} image(s) ({sizes}) as base colour of {len(textured)} material(s) ({sets}"
               + (f"; KHR_texture_transform on {moved}" if moved else "") + ")")
    else:
        tex = "no base-colour textures"
    occluded = sum(1 for m in scene.document.gltf.materials if m.occlusionTexture is not None)
    emissive = sum(1 for m in used if scene.materials[m].emissive_texture is not None)
    if emissive:
        tex += f"; emissive textures on {emissive} material(s)"
    bent = sum(1 for m in used if scene.materials[m].normal_texture is not None)
    if bent:
        tex += f"; normal maps on {bent} material(s)"
    varied = sum(1 for m in used if scene.materials[m].metallic_roughness_texture is not None)
    if varied:
        tex += f"; metallic-roughness textures on {varied} material(s)"
    masked = sum(1 for m in used if scene.materials[m].alpha_mode == "MASK")
    if masked:
        tex += f"; alpha masks (holes rays pass) on {masked} material(s)"
    passing = sum(1 for m in used if scene.materials[m].transmission > 0 and scene.materials[m].kind != "dielectric")
    if passing:
        tex += f"; transmission (thin-walled: not bent, not tinted) on {passing} material(s)"
    solid = sum(1 for m in used if scene.materials[m].kind == "dielectric")
    if solid:
        tex += f"; refracting glass (KHR_materials_volume) on {solid} material(s)"
    blended = sum(1 for m in used if scene.materials[m].alpha_mode == "BLEND")
    if blended:
        tex += f"; alpha blending (rays pass 1 - alpha of the time) on {blended} material(s)"
    if occluded:  # baked ambient occlusion: the photons' own shadowing of indirect light (textures.py)
        tex += f"; occlusionTexture on {occluded} not applied (the photons compute occlusion)"
    n = len(scene.instances)
    smooth = sum(1 for i in scene.instances if i.attributes is not None and i.attributes.normals is not None)
    coloured = sum(1 for i in scene.instances if i.attributes is not None and i.attributes.color is not None)
    return [
        f"textures   {tex}",
        f"normals    {smooth} of {n} primitives carry NORMAL (smooth shading)"
        + ("; the rest are flat shaded" if smooth < n else ""),
        f"colours    {coloured} of {n} primitives carry COLOR_0 (multiplies the base colour)",
    ]
