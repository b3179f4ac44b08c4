"""KHR_draco_mesh_compression (pipeline/scene/draco.py): Draco-compressed copies of files
(tests/scene/draco_files.py, DracoPy's encoder) load as their originals do, to the encoder's
quantization: Khronos's RiggedSimple, skinned (joints and weights as Draco's generic attributes),
posed at several instants, and a textured, vertex-coloured quad; broken Draco data and data that
disagree with their accessors are one-line errors."""
from __future__ import annotations

import base64
import json

import numpy as np
import pytest
from click.testing import CliRunner

from pipeline.cli import main
from pipeline.errors import SceneError
from pipeline.scene import read_scene
from tests.conftest import QUAD, QUAD_FACES, basic_builder
from tests.scene.draco_files import compress
from tests.scene.test_khronos_samples import RIGGED_SIMPLE

BITS = 14  # the encoder's position quantization: an error of at most half a step of the bounds per axis


def _step(scene) -> float:
    v = np.concatenate([inst.vertices for inst in scene.instances])
    return float((v.max(0) - v.min(0)).max()) / (2 ** BITS - 1)


def test_a_compressed_skinned_figure_poses_as_the_original(tmp_path):
    original = read_scene(RIGGED_SIMPLE)
    packed = read_scene(compress(RIGGED_SIMPLE, tmp_path / "rigged_draco.gltf", quantization_bits=BITS))
    assert "KHR_draco_mesh_compression" in packed.document.gltf.extensionsRequired
    assert packed.document.gltf.accessors[packed.document.gltf.meshes[0].primitives[0].attributes.POSITION] \
        .bufferView is None  # nothing but the Draco data holds the positions
    step = _step(original)
    for t in np.linspace(0, original.timeline.duration, 5):
        a, b = original.pose(t), packed.pose(t)
        assert np.array_equal(a.faces, b.faces)
        np.testing.assert_allclose(b.vertices, a.vertices, atol=2 * step)  # the bones carry the small error
        np.testing.assert_allclose(b.corner_normals, a.corner_normals, atol=0.01)
    da, db = original.instances[0].deformation, packed.instances[0].deformation
    assert np.array_equal(da.joints, db.joints) and np.array_equal(da.weights, db.weights)


def test_compressed_texture_coordinates_and_colours(tmp_path):
    b = basic_builder()
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float) * 0.75
    colors = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], float)
    b.add_node("quad", b.add_mesh("quad", QUAD + [0, 0.5, 0], QUAD_FACES, material=0, texcoords={0: uv},
                                  colors=colors))
    src = b.write(tmp_path / "quad.glb")
    original, packed = read_scene(src), read_scene(compress(src, tmp_path / "quad_draco.gltf"))
    a, p = original.instances[1].attributes, packed.instances[1].attributes
    np.testing.assert_allclose(p.texcoords[0], a.texcoords[0], atol=1e-3)
    np.testing.assert_allclose(p.color, a.color, atol=1e-3)
    info = CliRunner().invoke(main, ["info", str(tmp_path / "quad_draco.gltf")])
    assert info.exit_code == 0 and "KHR_draco" not in info.output


def _edit(path, change):
    tree = json.loads(path.read_text())
    change(tree)
    path.write_text(json.dumps(tree))
    return path


def _draco(tree):
    return tree["meshes"][0]["primitives"][0]["extensions"]["KHR_draco_mesh_compression"]


def _corrupt(tree):
    view = tree["bufferViews"][_draco(tree)["bufferView"]]
    view["byteOffset"] = 0  # the figure's index bytes, not Draco data


def _unknown_id(tree):
    _draco(tree)["attributes"]["NORMAL"] = 99


def _fewer_vertices(tree):
    tree["accessors"][tree["meshes"][0]["primitives"][0]["attributes"]["NORMAL"]]["count"] = 95


def _varint(n: int) -> bytes:
    out = bytearray()
    while True:
        out.append((n & 0x7F) | (0x80 if n > 0x7F else 0))
        n >>= 7
        if not n:
            return bytes(out)


def _claims_two_billion_points(tree):
    """The Draco stream's own point count (sequential connectivity, bitstream 2.2: after the 11-byte
    header, the faces' and the points' counts as varints) set to 2^31: a few bytes that would ask
    the decoder for 24 GB of positions."""
    view = tree["bufferViews"][_draco(tree)["bufferView"]]
    uri = tree["buffers"][0]["uri"]
    blob = bytearray(base64.b64decode(uri.split(",", 1)[1]))
    data = bytes(blob[view["byteOffset"]: view["byteOffset"] + view["byteLength"]])
    assert data[:5] == b"DRACO" and data[5:7] == b"\x02\x02" and data[8] == 0  # v2.2, sequential
    at = 11
    for _ in range(2):  # skip the two varints
        while data[at] & 0x80:
            at += 1
        at += 1
    faces = np.frombuffer(data[11:at], np.uint8)
    n_faces = sum(int(b & 0x7F) << (7 * i) for i, b in enumerate(faces[: np.argmax(faces < 0x80) + 1]))
    bomb = data[:11] + _varint(n_faces) + _varint(2**31) + data[at:]
    view["byteOffset"], view["byteLength"] = len(blob), len(bomb)
    blob += bomb
    tree["buffers"][0] = {"byteLength": len(blob),
                          "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(blob)).decode()}


@pytest.mark.parametrize("change, match", [
    (_claims_two_billion_points, r"KHR_draco_mesh_compression.bufferView: the [\d,]+ bytes of bufferView \d+ are "
                                 r"not Draco data"),
    (_corrupt, r"KHR_draco_mesh_compression.bufferView: the [\d,]+ bytes of bufferView \d+ are not Draco data"),
    (_unknown_id, r"KHR_draco_mesh_compression.attributes.NORMAL: the Draco data have no attribute with unique "
                  r"id 99"),
    (_fewer_vertices, r"KHR_draco_mesh_compression.attributes.NORMAL: the Draco data decode to 96 x 3 values, "
                      r"accessor 2 describes 95 x 3"),
])
def test_draco_data_that_do_not_fit_are_a_one_line_error(tmp_path, change, match):
    path = _edit(compress(RIGGED_SIMPLE, tmp_path / "bad.gltf"), change)
    with pytest.raises(SceneError, match=r"meshes\[0\].primitives\[0\].extensions." + match) as err:
        read_scene(path)
    assert "\n" not in str(err.value)
