import common  # noqa: F401  (numba's cache folder for this version of the sources, before any kernel)
