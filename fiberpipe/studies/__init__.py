"""Parameter sweeps: what accuracy costs in wall time (SPEC section 9)."""
