"""One writable-location check for --out and --store (pipeline/paths.py)."""
from __future__ import annotations

import pytest

from pipeline.errors import LoomError
from pipeline.paths import check_writable_dir
from pipeline.run.render import check_out_dir
from pipeline.run.shoot import check_store_location


def test_a_new_or_existing_directory_passes(tmp_path):
    check_writable_dir(tmp_path, field="--out")
    check_writable_dir(tmp_path / "new" / "deeper", field="--out")


@pytest.mark.parametrize("check, field", [(check_out_dir, "--out"), (check_store_location, "--store")])
def test_a_file_or_a_path_below_a_file_is_refused_naming_the_option(tmp_path, check, field):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    for where in (blocker, blocker / "below"):
        with pytest.raises(LoomError) as err:
            check(where if check is check_out_dir else str(where))
        assert err.value.field == field and err.value.path == str(where)
