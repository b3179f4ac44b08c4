"""Running a render: the Dask cluster, the per-segment coordinator, `loom render`, `loom shoot` and the
make-driven farm. The only package that imports ``distributed``."""
