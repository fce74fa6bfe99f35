"""The beam model built from traced fibers: meshing and exports."""
