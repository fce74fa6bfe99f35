"""Writers for the formats users open elsewhere: VTK (ParaView) and Abaqus input files."""
