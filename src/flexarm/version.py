"""flexarm's version, one source: the package metadata and the code read it here."""

__version__ = "0.1.0"
