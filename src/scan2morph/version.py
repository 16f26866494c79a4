"""The installed package's version (the store and the report record it)."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("scan2morph")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
