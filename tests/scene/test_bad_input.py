"""Malformed scenes give one-line errors naming the file and the problem, and `loom info` exits non-zero."""
from __future__ import annotations

import json
import struct
import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner

from pipeline.cli import main
from pipeline.errors import SceneError
from pipeline.scene import read_scene
from tests.conftest import QUAD, basic_builder


def _glb_parts(builder):
    raw = builder.to_glb_bytes()
    jlen = struct.unpack_from("<I", raw, 12)[0]
    doc = json.loads(raw[20 : 20 + jlen])
    return raw, doc


def _pack_glb(doc: dict, binary: bytes) -> bytes:
    j = json.dumps(doc).encode()
    j += b" " * (-len(j) % 4)
    binary += b"\0" * (-len(binary) % 4)
    body = struct.pack("<II", len(j), 0x4E4F534A) + j + struct.pack("<II", len(binary), 0x004E4942) + binary
    return struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body


def _binary(raw: bytes) -> bytes:
    jlen = struct.unpack_from("<I", raw, 12)[0]
    blen = struct.unpack_from("<I", raw, 20 + jlen)[0]
    return raw[28 + jlen : 28 + jlen + blen]


def _truncated(tmp_path):
    raw, _ = _glb_parts(basic_builder())
    (tmp_path / "bad.glb").write_bytes(raw[: len(raw) // 2])


def _wrong_magic(tmp_path):
    raw, _ = _glb_parts(basic_builder())
    (tmp_path / "bad.glb").write_bytes(b"gLTf" + raw[4:])


def _broken_json(tmp_path):
    raw, doc = _glb_parts(basic_builder())
    text = json.dumps(doc)[:-7]
    j = text.encode() + b" " * (-len(text) % 4)
    bin_part = raw[20 + struct.unpack_from("<I", raw, 12)[0]:]
    body = struct.pack("<II", len(j), 0x4E4F534A) + j + bin_part
    (tmp_path / "bad.glb").write_bytes(struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body)


def _missing_buffer(tmp_path):
    path = basic_builder().write(tmp_path / "bad.gltf", external_buffer=True)
    for f in tmp_path.glob("*.bin"):
        f.unlink()
    return path


def _accessor_out_of_range(tmp_path):
    raw, doc = _glb_parts(basic_builder())
    doc["accessors"][0]["count"] = 10_000
    (tmp_path / "bad.glb").write_bytes(_pack_glb(doc, _binary(raw)))


def _nan_vertex(tmp_path):
    raw, doc = _glb_parts(basic_builder())
    binary = bytearray(_binary(raw))
    position = doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]
    view = doc["bufferViews"][doc["accessors"][position]["bufferView"]]
    start = view.get("byteOffset", 0) + doc["accessors"][position].get("byteOffset", 0) + 12  # vertex 1, x
    binary[start : start + 4] = struct.pack("<f", float("nan"))
    doc["accessors"][position].pop("min", None)
    doc["accessors"][position].pop("max", None)
    (tmp_path / "bad.glb").write_bytes(_pack_glb(doc, bytes(binary)))


def _lines_primitive(tmp_path):
    b = basic_builder()
    b.add_node("wire", b.add_mesh("wire", QUAD, np.array([0, 1, 1, 2]), material=0, mode=1))
    b.write(tmp_path / "bad.glb")


def _unsupported_required_extension(tmp_path):
    raw, doc = _glb_parts(basic_builder())
    doc["extensionsRequired"] = ["EXT_lights_image_based"]
    doc.setdefault("extensionsUsed", []).append("EXT_lights_image_based")
    (tmp_path / "bad.glb").write_bytes(_pack_glb(doc, _binary(raw)))


CASES = {
    "truncated": (_truncated, "truncated"),
    "wrong-magic": (_wrong_magic, "wrong magic"),
    "broken-json": (_broken_json, "broken JSON"),
    "missing-buffer": (_missing_buffer, "missing buffer file"),
    "accessor-out-of-range": (_accessor_out_of_range, "out of range"),
    "nan-vertex": (_nan_vertex, "NaN"),
    "lines": (_lines_primitive, "LINES is not supported"),
    "extension": (_unsupported_required_extension, "EXT_lights_image_based"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_scene_gives_one_line_error(tmp_path, case):
    make, words = CASES[case]
    path = make(tmp_path) or tmp_path / "bad.glb"
    with pytest.raises(SceneError) as err:
        read_scene(path)
    message = str(err.value)
    assert str(path) in message and words in message and "\n" not in message

    result = CliRunner().invoke(main, ["info", str(path)])
    assert result.exit_code == 2
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("loom: error: ") and str(path) in lines[0]


def test_zero_area_triangles_are_dropped_and_counted(tmp_path):
    b = basic_builder()
    pts = np.array([[0, 1, 0], [1, 1, 0], [2, 1, 0], [0, 1, 1], [1, 1, 1], [0, 2, 1]], float)
    # triangle 0 collinear, triangle 1 repeats a vertex, triangle 2 is fine
    b.add_node("degenerate", b.add_mesh("degenerate", pts, np.array([0, 1, 2, 3, 3, 4, 3, 4, 5]), material=0))
    b.write(tmp_path / "zero.glb")
    scene = read_scene(tmp_path / "zero.glb")
    assert scene.dropped_triangles == 2
    assert scene.n_triangles == 3
    inst = scene.instances[-1]
    assert inst.source_faces.tolist() == [2]
    result = CliRunner().invoke(main, ["info", str(tmp_path / "zero.glb")])
    assert result.exit_code == 0 and "2 zero-area dropped" in result.output


def test_console_script_exit_status(tmp_path):
    """The installed `loom` entry point itself exits non-zero with one line on stderr."""
    path = tmp_path / "broken.glb"
    path.write_bytes(b"not a glb at all")
    proc = subprocess.run([sys.executable, "-m", "pipeline", "info", str(path)], capture_output=True, text=True)
    assert proc.returncode == 2
    assert proc.stdout == "" and len(proc.stderr.strip().splitlines()) == 1
    assert "broken.glb" in proc.stderr and "wrong magic" in proc.stderr


def test_unknown_camera_name(tmp_path, basic_scene_file):
    with pytest.raises(SceneError, match="no camera named 'nope'"):
        read_scene(basic_scene_file, camera="nope")
