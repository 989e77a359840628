"""arsim: a simulator of a mobile AR app that captures real-world light and renders virtual objects with it."""

__version__ = "0.1.0"
