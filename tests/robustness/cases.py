"""A generator of malformed and unusual scenes and command lines, each with what it must give.

Every case starts from one small, valid scene (a floor, a box, a point light and a camera, written by
the real builder) and changes one thing: the GLB container, the JSON's shapes, accessors and buffer
views (glTF 2.0 §3.6-§3.7 and the validation rules of §5), URIs, nodes, materials, lights, animation
and timeline, or the command line. ``expect`` is ``"ok"`` (the command succeeds) or ``"error"`` (one
line, ``loom: error: ...``, exit 2), with ``says`` a fragment the line must contain: the field or the
reason, so a case cannot pass on an unrelated error.
"""
from __future__ import annotations

import base64
import json
import os
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from pipeline.scene.builtin import shapes
from pipeline.scene.builtin.gltf_builder import GltfBuilder

# Command-line arguments of the tiny render every scene case goes through as well
TINY_RENDER = ["--frames", "1", "--resolution", "16x12", "--spp", "1", "--photons", "2000",
               "--scheduler", "synchronous", "--quiet"]


@dataclass
class Case:
    name: str
    expect: str  # "ok" or "error"
    says: str = ""  # a fragment the error line must contain
    make: Callable[[Path], Path] | None = None  # writes the scene into a folder, returns its path
    info_args: list[str] = field(default_factory=list)  # extra `loom info` arguments
    render_args: list[str] | None = None  # extra `loom render` arguments (None: none)
    command: str | None = None  # "render" or "info": the case is about a command line, not a scene


# --- the valid base scene and its pieces ------------------------------------------------------------

def base_builder(frames: int = 2) -> GltfBuilder:
    b = GltfBuilder()
    white = b.add_material("white", (0.7, 0.7, 0.7))
    floor = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], float)
    b.add_node("floor", b.add_mesh("floor", floor, np.array([0, 2, 1, 0, 3, 2]), material=white))
    b.add_node("box", b.add_mesh("box", *shapes.box((0.4, 0.4, 0.4), (0, 0.2, 0)), material=white))
    b.add_node("lamp", light=b.add_point_light("lamp", (1, 1, 1), 10.0), translation=(0.3, 1.5, 0.2))
    eye = (0.0, 1.0, 2.5)
    b.add_node("cam", camera=b.add_camera("cam", 0.9, 0.05),
               translation=eye, rotation=shapes.look_at(eye, (0, 0.2, 0)))
    b.set_scene_extras({"photonloom": {"element_size": 0.5, "frames": frames, "fps": 30}})
    return b


def split_glb(raw: bytes) -> tuple[dict, bytes]:
    jlen = struct.unpack_from("<I", raw, 12)[0]
    doc = json.loads(raw[20:20 + jlen])
    blen = struct.unpack_from("<I", raw, 20 + jlen)[0]
    return doc, raw[28 + jlen:28 + jlen + blen]


def pack_glb(doc: dict | str | bytes, binary: bytes) -> bytes:
    j = doc if isinstance(doc, bytes) else (doc if isinstance(doc, str) else json.dumps(doc)).encode()
    j += b" " * (-len(j) % 4)
    binary += b"\0" * (-len(binary) % 4)
    body = struct.pack("<II", len(j), 0x4E4F534A) + j + struct.pack("<II", len(binary), 0x004E4942) + binary
    return struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body


def _draco_garbage(doc, _binary) -> None:
    """The floor's primitive said to be Draco-compressed, its bufferView the positions' own bytes."""
    prim = doc["meshes"][0]["primitives"][0]
    prim["extensions"] = {"KHR_draco_mesh_compression": {"bufferView": 0, "attributes": {"POSITION": 0}}}
    doc["extensionsRequired"] = ["KHR_draco_mesh_compression"]


def _base() -> tuple[dict, bytes]:
    return split_glb(base_builder().to_glb_bytes())


def _position_accessor(doc) -> int:
    return doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]


def glb(change: Callable[[dict, bytes], object]) -> Callable[[Path], Path]:
    """A case writer: the base scene's JSON and binary chunk, changed in place (or replaced by
    what ``change`` returns: a (doc, binary) pair, or the whole file's bytes)."""
    def make(folder: Path) -> Path:
        doc, binary = _base()
        out = change(doc, binary)
        if isinstance(out, tuple) and len(out) == 2 and isinstance(out[0], dict) and isinstance(out[1], bytes):
            doc, binary = out
        raw = out if isinstance(out, bytes) else pack_glb(doc, binary)
        path = folder / "scene.glb"
        path.write_bytes(raw)
        return path
    return make


def gltf(change: Callable[[dict, Path], None]) -> Callable[[Path], Path]:
    """A case writer for a ``.gltf`` with its buffer in ``scene.bin`` beside it, then changed."""
    def make(folder: Path) -> Path:
        doc, binary = _base()
        (folder / "scene.bin").write_bytes(binary)
        doc["buffers"][0]["uri"] = "scene.bin"
        change(doc, folder)
        path = folder / "scene.gltf"
        path.write_text(json.dumps(doc))
        return path
    return make


def _set(path: str, value) -> Callable[[dict, bytes], None]:
    """Set ``doc[a][b]...`` from a dotted path with integer parts for list indices."""
    def change(doc, _binary):
        parts = [int(p) if p.isdigit() else p for p in path.split(".")]
        target = doc
        for p in parts[:-1]:
            target = target[p]
        target[parts[-1]] = value
    return change


def _extras(**fields) -> Callable[[dict, bytes], None]:
    def change(doc, _binary):
        doc["scenes"][0]["extras"]["photonloom"].update(fields)
    return change


def _animation(times, values, path="translation", interpolation="LINEAR", node=1):
    """Append an animation of node ``node`` with float accessors for ``times`` and ``values``."""
    def change(doc, binary):
        t = np.asarray(times, np.float32).tobytes()
        v = np.asarray(values, np.float32).tobytes()
        start = len(binary)
        binary = binary + t + v
        doc["buffers"][0]["byteLength"] = len(binary)
        nv = len(doc["bufferViews"])
        doc["bufferViews"] += [{"buffer": 0, "byteOffset": start, "byteLength": len(t)},
                               {"buffer": 0, "byteOffset": start + len(t), "byteLength": len(v)}]
        na = len(doc["accessors"])
        width = 4 if path == "rotation" else 3
        doc["accessors"] += [{"bufferView": nv, "componentType": 5126, "count": len(times), "type": "SCALAR"},
                             {"bufferView": nv + 1, "componentType": 5126, "count": len(values),
                              "type": f"VEC{width}"}]
        doc.setdefault("animations", []).append({
            "channels": [{"sampler": 0, "target": {"node": node, "path": path}}],
            "samplers": [{"input": na, "output": na + 1, "interpolation": interpolation}]})
        doc["scenes"][0]["extras"]["photonloom"].pop("frames", None)
        return doc, binary
    return change


def _indices(values):
    """Replace the floor's indices by an unsigned int accessor of ``values``."""
    def change(doc, binary):
        data = np.asarray(values, np.uint32).tobytes()
        doc["bufferViews"].append({"buffer": 0, "byteOffset": len(binary), "byteLength": len(data)})
        binary = binary + data
        doc["buffers"][0]["byteLength"] = len(binary)
        doc["accessors"].append({"bufferView": len(doc["bufferViews"]) - 1, "componentType": 5125,
                                 "count": len(values), "type": "SCALAR"})
        doc["meshes"][0]["primitives"][0]["indices"] = len(doc["accessors"]) - 1
        return doc, binary
    return change


def _view_of_positions(change_view: Callable[[dict, dict], None]):
    def change(doc, _binary):
        acc = doc["accessors"][_position_accessor(doc)]
        change_view(acc, doc["bufferViews"][acc["bufferView"]])
    return change


def _no_light_emissive(factor, strength=None):
    def change(doc, _binary):
        del doc["extensions"]["KHR_lights_punctual"]
        doc["extensionsUsed"] = [e for e in doc.get("extensionsUsed", []) if e != "KHR_lights_punctual"]
        doc["nodes"] = [n for n in doc["nodes"] if "extensions" not in n]
        doc["scenes"][0]["nodes"] = list(range(len(doc["nodes"])))
        doc["materials"][0]["emissiveFactor"] = factor
        if strength is not None:
            doc["materials"][0].setdefault("extensions", {})["KHR_materials_emissive_strength"] = {
                "emissiveStrength": strength}
    return change


def _raw_json(text: str):
    return lambda doc, binary: pack_glb(text, binary)


def _symlink_outside(doc, folder: Path):
    outside = folder.parent / "outside.bin"
    outside.write_bytes((folder / "scene.bin").read_bytes())
    (folder / "link.bin").symlink_to(outside)
    doc["buffers"][0]["uri"] = "link.bin"


def _fifo_buffer(doc, folder: Path):
    os.mkfifo(folder / "pipe.bin")
    doc["buffers"][0]["uri"] = "pipe.bin"


def _big_ground(doc, binary):
    """A 1e6-unit ground plane under the box (valid: real scenes have kilometre-wide ones)."""
    doc["nodes"][0]["scale"] = [5e5, 1.0, 5e5]
    doc["scenes"][0]["extras"]["photonloom"]["element_size"] = 5e4


def _strip(doc, binary):
    doc["meshes"][0]["primitives"][0]["mode"] = 5


def _data_uri(doc, binary):
    doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(binary).decode()
    return doc, b""


def _cycle(doc, binary):
    doc["nodes"][0]["children"] = [1]
    doc["nodes"][1]["children"] = [0]


def scene_cases() -> list[Case]:
    E, OK = "error", "ok"
    return [
        # GLB container (§4.4)
        Case("truncated glb", E, "truncated", glb(lambda d, b: pack_glb(d, b)[:200])),
        Case("wrong magic", E, "magic", glb(lambda d, b: b"gLTf" + pack_glb(d, b)[4:])),
        Case("container version 1", E, "version", glb(lambda d, b: pack_glb(d, b)[:4] + struct.pack("<I", 1)
                                                      + pack_glb(d, b)[8:])),
        Case("header length beyond file", E, "truncated", glb(lambda d, b: pack_glb(d, b)[:8]
                                                              + struct.pack("<I", 1 << 30) + pack_glb(d, b)[12:])),
        Case("empty file", E, "glTF", glb(lambda d, b: b"")),
        Case("first chunk is binary", E, "first chunk", glb(lambda d, b: pack_glb(d, b)[:16]
                                                            + struct.pack("<I", 0x004E4942) + pack_glb(d, b)[20:])),
        # JSON shapes
        Case("broken json", E, "JSON", glb(lambda d, b: pack_glb(json.dumps(d)[:-9], b))),
        Case("top level array", E, "JSON object", glb(_raw_json("[1, 2, 3]"))),
        Case("top level number", E, "JSON object", glb(_raw_json("42"))),
        Case("non-utf8 json", E, "JSON", glb(lambda d, b: pack_glb(b"{\xff\xfe}", b))),
        Case("deeply nested json", E, "JSON", glb(_raw_json("[" * 100_000 + "]" * 100_000))),
        Case("nodes is an object", E, "nodes", glb(_set("nodes", {"a": 1}))),
        Case("child index is a string", E, "nodes[0].children[0]", glb(_set("nodes.0.children", ["1"]))),
        Case("accessor count is a string", E, "count", glb(_set("accessors.0.count", "many"))),
        Case("accessor count is 4e8 float", E, "count", glb(_set("accessors.0.count", 4e8))),
        Case("NaN translation literal", E, "translation", glb(_raw_json(
            json.dumps(_base()[0]).replace('"translation": [0.3, 1.5, 0.2]', '"translation": [NaN, 1.5, 0.2]')))),
        Case("asset version 1.0", E, "asset.version", glb(_set("asset.version", "1.0"))),
        Case("unknown required extension", E, "extensionsRequired", glb(_set("extensionsRequired", ["EXT_magic"]))),
        Case("mesh index is a string", E, "mesh", glb(_set("nodes.0.mesh", "0"))),
        Case("materials are numbers", E, "materials[0]", glb(_set("materials", [1, 2]))),
        # Accessors and buffer views (§3.6, §5.1)
        Case("4e8 elements without a buffer view", E, "without a bufferView",
             glb(lambda d, b: d["accessors"][_position_accessor(d)].update(count=400_000_000, bufferView=None)
                 or d["accessors"][_position_accessor(d)].pop("bufferView"))),
        Case("huge count in a small view", E, "out of range",
             glb(_set("accessors.0.count", 2_000_000_000))),
        Case("negative byteStride", E, "byteStride", glb(_view_of_positions(lambda a, v: v.update(byteStride=-12)))),
        Case("byteStride below the element", E, "smaller than", glb(_view_of_positions(
            lambda a, v: v.update(byteStride=8)))),
        Case("byteStride not a multiple of 4", E, "multiple of 4", glb(_view_of_positions(
            lambda a, v: v.update(byteStride=14)))),
        Case("byteStride above 252", E, "252", glb(_view_of_positions(lambda a, v: v.update(byteStride=256)))),
        Case("negative accessor byteOffset", E, "byteOffset", glb(_view_of_positions(
            lambda a, v: a.update(byteOffset=-12)))),
        Case("negative view byteOffset", E, "byteOffset", glb(_view_of_positions(
            lambda a, v: v.update(byteOffset=-64)))),
        Case("view beyond its buffer", E, "spans bytes", glb(_view_of_positions(
            lambda a, v: v.update(byteLength=v["byteLength"] + 10_000)))),
        Case("misaligned accessor offset", E, "multiple of the component size", glb(_view_of_positions(
            lambda a, v: (a.update(byteOffset=2), v.update(byteLength=v["byteLength"] + 2))))),
        Case("accessor count 0", E, "count", glb(_set("accessors.0.count", 0))),
        Case("missing buffer view", E, "bufferView", glb(_set("accessors.0.bufferView", 99))),
        Case("missing buffer", E, "buffer", glb(_set("bufferViews.0.buffer", 7))),
        Case("unknown componentType", E, "componentType", glb(_set("accessors.0.componentType", 5130))),
        Case("type VEC7", E, "type", glb(_set("accessors.0.type", "VEC7"))),
        Case("float indices", E, "componentType", glb(lambda d, b: d["accessors"][
            d["meshes"][0]["primitives"][0]["indices"]].update(componentType=5126))),
        Case("index out of range", E, "out of range", glb(_indices([0, 1, 99]))),
        Case("POSITION is VEC2", E, "VEC3", glb(lambda d, b: d["accessors"][_position_accessor(d)].update(
            type="VEC2"))),
        Case("sparse accessor", E, "sparse", glb(lambda d, b: d["accessors"][0].update(
            sparse={"count": 1, "indices": {}, "values": {}}))),
        Case("buffer byteLength beyond data", E, "byteLength", glb(lambda d, b: d["buffers"][0].update(
            byteLength=len(b) + 4096))),
        Case("buffer byteLength 0", E, "byteLength", glb(lambda d, b: d["buffers"][0].update(byteLength=0))),
        Case("data URI not base64", E, "base64", glb(lambda d, b: (d["buffers"][0].update(
            uri="data:application/octet-stream,abc"), (d, b))[1])),
        Case("bad base64", E, "base64", glb(lambda d, b: (d["buffers"][0].update(
            uri="data:application/octet-stream;base64,@@@"), (d, b))[1])),
        Case("NaN vertex", E, "NaN", glb(lambda d, b: (d, b[:d["bufferViews"][d["accessors"][_position_accessor(d)][
            "bufferView"]].get("byteOffset", 0)] + struct.pack("<f", float("nan")) + b[d["bufferViews"][
            d["accessors"][_position_accessor(d)]["bufferView"]].get("byteOffset", 0) + 4:]))),
        # URIs: only files inside the scene's folder (and no devices or pipes)
        Case("buffer uri /etc/passwd", E, "outside the scene's folder", gltf(lambda d, f: d["buffers"][0].update(
            uri="/etc/passwd"))),
        Case("buffer uri ../", E, "outside the scene's folder", gltf(lambda d, f: d["buffers"][0].update(
            uri="../../../../etc/passwd"))),
        Case("percent-encoded ../", E, "outside the scene's folder", gltf(lambda d, f: d["buffers"][0].update(
            uri="%2e%2e/%2e%2e/etc/passwd"))),
        Case("buffer uri /dev/zero", E, "outside the scene's folder", gltf(lambda d, f: d["buffers"][0].update(
            uri="/dev/zero"))),
        Case("buffer uri file://", E, "relative file paths", gltf(lambda d, f: d["buffers"][0].update(
            uri="file:///etc/passwd"))),
        Case("buffer uri http://", E, "relative file paths", gltf(lambda d, f: d["buffers"][0].update(
            uri="http://127.0.0.1:9/scene.bin"))),
        Case("missing buffer file", E, "missing buffer file", gltf(lambda d, f: d["buffers"][0].update(
            uri="nothere.bin"))),
        Case("buffer uri is a folder", E, "not a regular file", gltf(lambda d, f: (
            (f / "sub").mkdir(), d["buffers"][0].update(uri="sub")))),
        Case("buffer is a named pipe", E, "not a regular file", gltf(_fifo_buffer)),
        Case("symlink leading outside", E, "outside the scene's folder", gltf(_symlink_outside)),
        Case("image uri outside", E, "images[0].uri", gltf(lambda d, f: d.update(
            images=[{"uri": "../../secret.png"}]))),
        Case("external buffer", OK, "", gltf(lambda d, f: None)),
        # Nodes (§3.5)
        Case("zero quaternion", E, "rotation", glb(_set("nodes.1.rotation", [0, 0, 0, 0]))),
        Case("node cycle", E, "cycle", glb(_cycle)),
        Case("node is its own child", E, "cycle", glb(_set("nodes.0.children", [0]))),
        Case("two parents", E, "two parents", glb(lambda d, b: (d["nodes"][0].update(children=[1]),
                                                                d["nodes"][2].update(children=[1])))),
        Case("child out of range", E, "children", glb(_set("nodes.0.children", [99]))),
        Case("matrix of 15 numbers", E, "matrix", glb(_set("nodes.0.matrix", [1.0] * 15))),
        Case("scale 1e38", E, "coordinates", glb(_set("nodes.0.scale", [1e38, 1.0, 1e38]))),
        Case("scale overflowing float32", E, "Inf", glb(_set("nodes.0.scale", [1e39, 1.0, 1e39]))),
        Case("scale 0 (a hidden node)", OK, "", glb(_set("nodes.0.scale", [0.0, 0.0, 0.0]))),
        Case("default scene out of range", E, "scene", glb(_set("scene", 5))),
        Case("mesh out of range", E, "mesh", glb(_set("nodes.0.mesh", 42))),
        Case("camera out of range", E, "camera", glb(_set("nodes.3.camera", 9))),
        Case("light out of range", E, "light", glb(_set("nodes.2.extensions.KHR_lights_punctual.light", 4))),
        # Materials and lights
        Case("negative emission", E, "emissiveFactor", glb(_no_light_emissive([-1.0, 0.0, 0.0]))),
        Case("negative emissive strength", E, "emissiveStrength", glb(_no_light_emissive([1.0, 1.0, 1.0], -5.0))),
        Case("NaN emission literal", E, "emissiveFactor", glb(lambda d, b: pack_glb(json.dumps(d).replace(
            '"name": "white"', '"name": "white", "emissiveFactor": [NaN, 0, 0]', 1), b))),
        Case("negative light intensity", E, "intensity", glb(_set("extensions.KHR_lights_punctual.lights.0.intensity",
                                                                  -3.0))),
        Case("light type area", E, "type", glb(_set("extensions.KHR_lights_punctual.lights.0.type", "area"))),
        Case("metallicFactor 2", E, "metallicFactor", glb(lambda d, b: d["materials"][0].setdefault(
            "pbrMetallicRoughness", {}).update(metallicFactor=2.0))),
        Case("no light at all, --light none", E, "no light",
             glb(lambda d, b: _no_light_emissive([0.0, 0.0, 0.0])(d, b)),
             info_args=["--light", "none"], render_args=["--light", "none"]),
        Case("no light at all: the default sun and sky", OK, "",
             glb(lambda d, b: _no_light_emissive([0.0, 0.0, 0.0])(d, b))),
        Case("material out of range", E, "material", glb(_set("meshes.0.primitives.0.material", 12))),
        # Animation and timeline
        Case("last key at 1e6 s", E, "frames", glb(_animation([0.0, 1e6], [[0, 0, 0], [1, 0, 0]]))),
        Case("frames 1e9", E, "frames", glb(_extras(frames=1_000_000_000))),
        Case("frames is a string", E, "frames", glb(_extras(frames="many"))),
        Case("frames 0", E, "frames", glb(_extras(frames=0))),
        Case("frames 2.5", E, "frames", glb(_extras(frames=2.5))),
        Case("fps 0", E, "fps", glb(_extras(fps=0))),
        Case("fps -30", E, "fps", glb(_extras(fps=-30))),
        Case("fps is a string", E, "fps", glb(_extras(fps="fast"))),
        Case("element_size is a string", E, "element_size", glb(_extras(element_size="big"))),
        Case("zero quaternion key", E, "zero quaternion", glb(_animation(
            [0.0, 1.0], [[0, 0, 0, 1], [0, 0, 0, 0]], path="rotation"))),
        Case("keys not increasing", E, "increase", glb(_animation([0.0, 0.0], [[0, 0, 0], [1, 0, 0]]))),
        Case("interpolation SMOOTH", E, "interpolation", glb(_animation([0.0, 1.0], [[0, 0, 0], [1, 0, 0]],
                                                                         interpolation="SMOOTH"))),
        Case("channel on a missing node", E, "node", glb(_animation([0.0, 1.0], [[0, 0, 0], [1, 0, 0]], node=77))),
        Case("100,000 frames", OK, "", glb(_animation([0.0, 3333.3], [[0, 0, 0], [0.5, 0, 0]]))),
        # Unusual but valid
        Case("kilometre-wide ground plane", OK, "", glb(_big_ground)),
        Case("triangle strip", OK, "", glb(_strip)),
        Case("data URI buffer", OK, "", glb(_data_uri)),
        Case("points mode", E, "mode", glb(_set("meshes.0.primitives.0.mode", 0))),
        # Extensions: compressed, instanced, hidden, masked, mirrored
        Case("Draco data that are not Draco", E, "not Draco data", glb(_draco_garbage)),
        Case("instancing attributes not an object", E, "EXT_mesh_gpu_instancing",
             glb(_set("nodes.1.extensions", {"EXT_mesh_gpu_instancing": {"attributes": 5}}))),
        Case("visible is a number", E, "visible",
             glb(_set("nodes.1.extensions", {"KHR_node_visibility": {"visible": 1}}))),
        Case("alphaMode CUTOUT", E, "alphaMode", glb(_set("materials.0.alphaMode", "CUTOUT"))),
        Case("a box hidden throughout", OK, "",
             glb(_set("nodes.1.extensions", {"KHR_node_visibility": {"visible": False}}))),
        Case("a mirrored box", OK, "", glb(_set("nodes.1.scale", [-1.0, 1.0, 1.0]))),
    ]


def command_cases() -> list[Case]:
    """Command lines over the valid base scene."""
    E, OK = "error", "ok"
    render = lambda name, says, *args: Case(name, E, says, render_args=list(args), command="render")  # noqa: E731
    return [
        render("frames 1-1000000000", "frames", "--frames", "1-1000000000"),
        render("--frames 0", "outside the timeline", "--frames", "0"),
        render("frames 5-1", "ends before", "--frames", "5-1"),
        render("frames step 0", "step", "--frames", "1-2x0"),
        render("frames abc", "cannot parse", "--frames", "abc"),
        render("workers -1", "--workers", "--scheduler", "local", "--workers", "-1"),
        render("workers 0", "--workers", "--scheduler", "local", "--workers", "0"),
        render("workers 100000", "--workers", "--scheduler", "local", "--workers", "100000"),
        render("out under /proc", "--out", "--out", "/proc/loom-robustness/out"),
        render("resolution 0x10", "--resolution", "--resolution", "0x10"),
        render("resolution 100000x100000", "--resolution", "--resolution", "100000x100000"),
        render("spp 0", "spp", "--spp", "0"),
        render("photons 0", "photons", "--photons", "0"),
        render("photons -5", "photons", "--photons", "-5"),
        render("scheduler bogus", "--scheduler", "--scheduler", "bogus"),
        render("fmax 100000", "--fmax", "--fmax", "100000"),
        render("segment -1", "--segment", "--segment", "-1"),
        render("camera nope", "no camera named", "--camera", "nope"),
        render("store on /dev/null", "--store", "--store", "/dev/null"),
        render("config missing", "cannot read", "--config", "/nonexistent/c.json"),
        Case("info element size -1", E, "element_size", info_args=["--element-size", "-1"], command="info"),
        Case("info element size 1e-9", E, "elements", info_args=["--element-size", "1e-9"], command="info"),
        Case("info element size 0.05", OK, "", info_args=["--element-size", "0.05"], command="info"),
    ]


def all_cases() -> list[Case]:
    return scene_cases() + command_cases()
