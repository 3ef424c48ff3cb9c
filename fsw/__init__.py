"""Flight software: one module per function of the paper (guidance, control, allocation,
fdir, jet driver, modes, executive). Plain algorithm code; no transport or clocks, and no
threads but the background-job runner's (jobs.py). The FSW never imports the plant (sim/)."""
import common  # noqa: F401  (numba's cache folder for this version of the sources, before any kernel)
