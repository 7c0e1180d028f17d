"""Prometheus metrics of the central server and the reaction chain (docs/metrics.md)."""
