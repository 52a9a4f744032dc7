"""The package version (a leaf: the outputs record it)."""
__version__ = "0.1.0"
