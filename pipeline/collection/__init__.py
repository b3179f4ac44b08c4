"""Temporal photon collection (§5.1, §5.2.4-5.2.5): windows per (frame, element), the batch sums
the gather reads, the estimator maths, the adaptive filter: stored photons in, illumination maps out."""
