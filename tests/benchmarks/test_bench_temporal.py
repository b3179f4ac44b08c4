"""``loom bench temporal`` (pipeline/benchmarks/temporal.py) runs the gather path renders run and
measures what its NumPy twin computes: a small run on the real ATRIUM element mesh."""
from __future__ import annotations

import numpy as np

from pipeline.benchmarks.temporal import FMAX, run


def test_bench_temporal_times_the_path_renders_run():
    lines = []
    result = run(trace_frames=1, numpy_frames=1, n_frames=40, echo=lines.append)
    # The PoCL window and vertex flux of the timed rows is its twin's (linear windows, as renders)
    assert result["flux_twin_difference"] < 1e-6
    assert all(result["ms_per_frame"][k] > 0 for k in ("windows", "sums", "flux", "filter"))
    assert all(v > 0 for v in result["numpy_ms_per_frame"].values())
    assert 1 <= result["mean_window"] <= FMAX + 1
    assert result["records_per_s_gather_1M"] > 0 and result["trace_ms"] > 0
    assert np.isfinite(result["unfiltered_irradiance_max"]) and result["unfiltered_irradiance_max"] > 0
    assert any(line.startswith("PoCL ms/frame: windows") for line in lines)
