"""Code shared by the plant and the flight software: attitude math, frames, atmosphere
models and data-file loading. Nothing here knows about processes or transports."""
