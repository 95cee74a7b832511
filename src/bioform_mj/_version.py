"""The package version, in a module of its own: modules that record it import it from here, not from
the package (whose ``__init__`` imports them lazily: no cycle)."""

__version__ = "0.1.0"
