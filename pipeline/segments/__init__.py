"""Segments (§5.2): the pure decisions (Eq. (2), p_me against p_thr, d_AQM against d_thr, placement)
and the segment records on disk; the coordinator that acts on them is pipeline/run/coordinator.py."""
