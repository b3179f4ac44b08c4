"""EXT_meshopt_compression (pipeline/scene/meshopt.py): meshoptimizer-compressed copies of files
(tests/scene/meshopt_files.py, the ``meshopt`` package's encoder, as gltfpack writes them) load as
their originals do: Khronos's RiggedSimple, every view compressed and its fallback buffer empty,
poses to the bit at several instants (triangles up to the index codec's rotation of their corners);
normals through the octahedral filter within their 8 bits; broken data, a view claiming more than
its bytes can expand to, bad modes and a data-less buffer not marked as a fallback are one-line
errors."""
from __future__ import annotations

import base64
import json

import meshopt
import numpy as np
import pytest
from click.testing import CliRunner

from pipeline.cli import main
from pipeline.errors import SceneError
from pipeline.scene import read_scene
from tests.conftest import QUAD, QUAD_FACES, basic_builder
from tests.scene.meshopt_files import EXTENSION, compress
from tests.scene.test_khronos_samples import RIGGED_SIMPLE


def _rotated_to_least(faces: np.ndarray) -> np.ndarray:
    """Each triangle's corners rotated to start at its least index: the winding kept, the start not."""
    k = np.argmin(faces, axis=1)
    return np.stack([np.roll(f, -r) for f, r in zip(faces, k)])


def test_a_compressed_skinned_figure_poses_as_the_original_to_the_bit(tmp_path):
    original = read_scene(RIGGED_SIMPLE)
    packed = read_scene(compress(RIGGED_SIMPLE, tmp_path / "rigged_meshopt.gltf"))
    doc = packed.document
    assert EXTENSION in doc.gltf.extensionsRequired and doc.buffers[-2] == b""  # the fallback holds nothing
    assert len(doc.views) == len(doc.gltf.bufferViews)
    for t in np.linspace(0, original.timeline.duration, 5):
        a, b = original.pose(t), packed.pose(t)
        assert np.array_equal(a.vertices, b.vertices)
        assert np.array_equal(_rotated_to_least(a.faces), _rotated_to_least(b.faces))
    da, db = original.instances[0].deformation, packed.instances[0].deformation
    assert np.array_equal(da.joints, db.joints) and np.array_equal(da.weights, db.weights)
    info = CliRunner().invoke(main, ["info", str(tmp_path / "rigged_meshopt.gltf")])
    assert info.exit_code == 0 and EXTENSION not in info.output


def _uri(data: bytes) -> str:
    return "data:application/octet-stream;base64," + base64.b64encode(data).decode()


def test_octahedral_normals_decode_within_their_bits(tmp_path):
    # The floor's four normals tilted apart, stored as gltfpack stores them: 8-bit octahedral, in
    # rows of 4 bytes, the filter undone by the decoder (KHR_mesh_quantization's normalized bytes)
    normals = np.array([[0.3, 0.9, 0.1], [-0.2, 0.95, 0.0], [0.0, 0.8, -0.6], [0.1, 1.0, 0.1]])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    b = basic_builder(light=True)
    b.add_node("quad", b.add_mesh("quad", QUAD, QUAD_FACES, normals=normals.astype(np.float32)))
    path = b.write(tmp_path / "quad.gltf")
    tree = json.loads(path.read_text())
    rows = meshopt.encode_filter_oct(np.c_[normals, np.zeros(4)].astype(np.float32), 4, 8)
    encoded = meshopt.encode_gltf_buffer(rows.view(np.uint32), "ATTRIBUTES")
    tree["buffers"] += [{"byteLength": 16, "extensions": {EXTENSION: {"fallback": True}}},
                        {"byteLength": len(encoded), "uri": _uri(encoded)}]
    n = len(tree["buffers"])
    tree["bufferViews"].append({"buffer": n - 2, "byteLength": 16, "byteStride": 4, "extensions": {EXTENSION: {
        "buffer": n - 1, "byteLength": len(encoded), "byteStride": 4, "count": 4, "mode": "ATTRIBUTES",
        "filter": "OCTAHEDRAL"}}})
    tree["accessors"].append({"bufferView": len(tree["bufferViews"]) - 1, "componentType": 5120, "normalized": True,
                              "count": 4, "type": "VEC3"})
    tree["meshes"][-1]["primitives"][0]["attributes"]["NORMAL"] = len(tree["accessors"]) - 1
    for key in ("extensionsUsed", "extensionsRequired"):
        tree[key] = [EXTENSION, "KHR_mesh_quantization"]
    path.write_text(json.dumps(tree))
    scene = read_scene(path)
    decoded = scene.instances[-1].attributes.normals
    np.testing.assert_allclose(decoded / np.linalg.norm(decoded, axis=1, keepdims=True), normals, atol=0.02)


def _edit(path, change):
    tree = json.loads(path.read_text())
    change(tree)
    path.write_text(json.dumps(tree))
    return path


def _ext(tree, view=2):
    return tree["bufferViews"][view]["extensions"][EXTENSION]


def _garbage(tree):
    buf = tree["buffers"][-1]
    data = bytearray(base64.b64decode(buf["uri"].split(",", 1)[1]))
    start = _ext(tree)["byteOffset"]
    data[start:start + _ext(tree)["byteLength"]] = bytes(_ext(tree)["byteLength"])  # zeros: not the codec's header
    buf["uri"] = _uri(bytes(data))


def _claims_a_gigabyte(tree):
    _ext(tree)["count"] = 1 << 26  # x 12 bytes: 768 MiB from 2 KB
    tree["bufferViews"][2]["byteLength"] = (1 << 26) * 12


def _bad_mode(tree):
    _ext(tree)["mode"] = "VERTICES"


def _not_a_fallback(tree):
    del tree["buffers"][-2]["extensions"]


@pytest.mark.parametrize("change, match", [
    (_garbage, r"bufferViews\[2\].extensions.EXT_meshopt_compression: the [\d,]+ bytes are not ATTRIBUTES data "
               r"that decode"),
    (_claims_a_gigabyte, r"bufferViews\[2\].extensions.EXT_meshopt_compression: count 67108864 x byteStride 12 "
                         r"claims 805,306,368 bytes from [\d,]+ compressed bytes"),
    (_bad_mode, r"bufferViews\[2\].extensions.EXT_meshopt_compression.mode: 'VERTICES' is not one of ATTRIBUTES"),
    (_not_a_fallback, r"buffers\[\d\]: has no uri and there is no GLB binary chunk"),
])
def test_meshopt_data_that_do_not_fit_are_a_one_line_error(tmp_path, change, match):
    path = _edit(compress(RIGGED_SIMPLE, tmp_path / "bad.gltf"), change)
    with pytest.raises(SceneError, match=match) as err:
        read_scene(path)
    assert "\n" not in str(err.value)
