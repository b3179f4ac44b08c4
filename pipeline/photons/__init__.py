"""The photon stage (§4): emission tables, Embree hits and the wavefront tracer of one frame's batch."""
