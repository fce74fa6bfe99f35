"""Post-processing of a simulation: curves, energies, geometry, position error, plots, report."""
