"""Flight software: one module per function of the paper (guidance, control, allocation,
fdir, jet driver, modes, executive). Plain algorithm code; no transport, threads or clocks.
The FSW never imports the plant (sim/)."""
