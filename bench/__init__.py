"""Benchmarks, run on demand: ``guidebot bench NAME --json`` prints one JSON object last."""
