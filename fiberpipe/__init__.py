"""fiberpipe: from a tomography volume of a fiber bundle to its simulated compaction curve."""

__version__ = "0.1.0"
