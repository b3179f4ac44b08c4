"""Segments (§5.2): the pure decisions (Eq. (2), p_me against p_thr, d_AQM against d_thr, placement),
the planner that runs them for one segment at a time against an executor that traces its photons,
the render's Job and the segment records on disk. Nothing here touches Dask: the planner's Dask
executor is pipeline/run/coordinator.py."""
