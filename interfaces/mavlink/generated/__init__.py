"""Generated MAVLink bindings (do not edit; regenerate with python -m interfaces.mavlink.generate)."""
