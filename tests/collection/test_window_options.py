"""Errors at the boundary: kernels/temporal.py refuses a bad mode or F_max with ValueError (no CLI
wording); pipeline/collection/maps.py's WindowSpec turns the user's --temporal / --fmax into a LoomError
naming the option before the kernel runs."""
from __future__ import annotations

import numpy as np
import pytest

from kernels.temporal import windows_cl
from pipeline.collection.maps import WindowSpec, collection_windows
from pipeline.config import CollectionConfig
from pipeline.errors import LoomError

COUNTS = np.ones((5, 3), np.uint32)
EMITTED = np.full(5, 100.0)


@pytest.mark.parametrize("kw, field", [(dict(mode="sometimes", fmax=4), "--temporal"),
                                       (dict(mode="adaptive", fmax=600), "--fmax"),
                                       (dict(mode="fixed", fmax=-2), "--fmax")])
def test_the_pipeline_names_the_option(kw, field):
    with pytest.raises(LoomError) as err:
        WindowSpec(**kw)
    assert err.value.field == field
    with pytest.raises(ValueError) as raw:  # the kernel's own contract, without the CLI's words
        windows_cl(COUNTS, EMITTED, **kw)
    assert not isinstance(raw.value, LoomError) and "--" not in str(raw.value)


def test_good_options_pass_through():
    back, fwd = collection_windows(COUNTS, EMITTED, [1, 2], WindowSpec(mode="fixed", fmax=4), CollectionConfig())
    assert back.tolist() == [[1, 1, 1], [2, 2, 2]] and fwd.tolist() == [[2, 2, 2], [2, 2, 2]]
