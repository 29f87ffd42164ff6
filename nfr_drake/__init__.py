"""nfr-drake: neural field representations of articulated objects for manipulation planning."""

__version__ = "0.1.0"
