"""The package version: one home, below every layer (result files and checks record it)."""

__version__ = "0.1.0"
