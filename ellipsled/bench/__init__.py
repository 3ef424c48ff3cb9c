"""Benchmarks: one module per area, each exporting ``run(quick: bool) -> dict`` whose
figures sit next to a baseline measured in the same invocation (docs/benchmarks.md)."""
