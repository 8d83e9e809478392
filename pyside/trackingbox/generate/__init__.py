"""gen-trackingbox: Modelica tracking box and tracked model from a spec with pairs.

:func:`~.generator.generate` writes the ``<Twin>Tracking`` package,
:func:`~.generator.compile_generated` compiles its tracked model;
:mod:`.filters` formats Python values as Modelica literals and :mod:`.source`
inspects (or patches) the twin's Modelica source.
"""
from __future__ import annotations

from .generator import GenerateResult, compile_generated, generate

__all__ = ["GenerateResult", "compile_generated", "generate"]
