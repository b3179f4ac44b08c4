"""Benchmarks behind ``loom bench``: speed is measured here, never asserted in tests."""
