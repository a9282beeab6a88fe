"""The package version, in one place (read by the writers that stamp files)."""

__version__ = "0.1.0"
