"""The package's version, in a module of its own.

Everything that prints or embeds the version (``trackingbox --version``, the
headers of generated Modelica) imports it from here, never from the package
``__init__``: a submodule reading the package root while the root's
``__init__`` is still importing that submodule is an import cycle.
"""
from __future__ import annotations

__version__ = "0.1.0"
