"""Parameter sweeps: what accuracy costs in wall time (docs/accuracy-cost.md)."""
