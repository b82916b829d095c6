"""What every stage leans on and no stage owns: the time budget of a solve (``budget``), the
on-disk caches and the numba kernels' machine code (``caching``), CSV rows (``csvrows``)."""
