"""Frame lists and steps with fixed photons render exactly the frames they name (a reconstruction
chunk never spans a gap, so no gather reads a frame that was not traced)."""
from __future__ import annotations

import pytest
from click.testing import CliRunner

from pipeline.cli import main
from pipeline.frames.images import frame_paths
from pipeline.run.coordinator import frame_chunks


def test_chunks_break_at_gaps_and_at_the_chunk_size():
    assert frame_chunks([1, 3]) == [[1], [3]]
    assert frame_chunks([1, 2, 3, 5, 6], size=2) == [[1, 2], [3], [5, 6]]
    assert frame_chunks(list(range(1, 20)), size=16) == [list(range(1, 17)), [17, 18, 19]]


@pytest.fixture(scope="module")
def cornell(tmp_path_factory):
    path = tmp_path_factory.mktemp("cornell") / "c.glb"
    result = CliRunner().invoke(main, ["scene", "cornell", "-o", str(path)])
    assert result.exit_code == 0, result.output
    return path


@pytest.mark.parametrize("frames, named", [("1,3", [1, 3]), ("1,10,20,30", [1, 10, 20, 30]),
                                           ("1-30x7", [1, 8, 15, 22, 29]), ("2-4,9", [2, 3, 4, 9])])
def test_a_frame_list_with_fixed_photons_renders_what_it_names(cornell, tmp_path, frames, named):
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["render", str(cornell), "--out", str(out), "--frames", frames,
                                       "--photons", "3000", "--resolution", "32x24", "--scheduler", "synchronous"])
    assert result.exit_code == 0, result.output
    assert "Traceback" not in result.output and "Error" not in result.stderr
    written = sorted(int(p.name.split(".")[1]) for p in out.glob("beauty.*.png"))
    assert written == named
    assert all(frame_paths(out, f)[0].is_file() for f in named)
