"""``Modelica.Blocks.Continuous.Internal.Filter.base.ChebyshevI`` given to rumoca with a body it takes.

rumoca 0.10.2 stops with "missing function value definition" (in ToDae, no position) on a ``for``
loop inside an if-statement whose condition it evaluates while flattening (``if size(cr, 1) == 0``,
``if normalized`` with the block's parameter): MSL 4.0.0's ``ChebyshevI`` (``Blocks/Continuous.mo``,
line 2118) computes the denominator coefficients of its second-order factors so, one loop per branch,
and scales them by the normalisation factor in a loop under ``if normalized``. The body below
computes the same coefficients with the branches moved into if-expressions inside one loop, and the
scaling done unconditionally with ``alpha = 1`` where the filter is not normalised (multiplying by 1
leaves them as they are). The factor itself is the MSL's ``normalizationFactor``, whose ``while``
loops :mod:`.while_loops` compiles.

The entry is a :class:`.rewrite.LibraryBody`'s keyword arguments (``rewrite.LIBRARY_BODIES`` adds
it); the digest is that of MSL 4.0.0's text, so any other text is left as it stands.
"""
from __future__ import annotations

LIBRARY_BODIES = (
    dict(
        name="Modelica.Blocks.Continuous.Internal.Filter.base.ChebyshevI",
        header=b"function ChebyshevI",
        digest="0056818c7904f1912e1b6ed94a1bedf43aca34a9a43cf40afb047e9a18adb931",
        start=b"algorithm",
        until=b"end ChebyshevI",
        body=b"""algorithm
  epsilon := sqrt(10^(A_ripple/10) - 1);
  fac := asinh(1/epsilon)/order;
  den1 := fill(1/sinh(fac), size(den1, 1));
  for i in 1:size(c0, 1) loop
    den2[i, 1] := 1/(cosh(fac)^2 - (if size(cr, 1) == 0 then cos((2*i - 1)*pi/(2*order))
                                    else cos(i*pi/order))^2);
    den2[i, 2] := 2*den2[i, 1]*sinh(fac)*(if size(cr, 1) == 0 then cos((2*i - 1)*pi/(2*order))
                                          else cos(i*pi/order));
  end for;
  alpha := if normalized then
    Modelica.Blocks.Continuous.Internal.Filter.Utilities.normalizationFactor(den1, den2) else 1.0;
  alpha2 := alpha*alpha;
  for i in 1:size(c0, 1) loop
    den2[i, 1] := den2[i, 1]*alpha2;
    den2[i, 2] := den2[i, 2]*alpha;
  end for;
  den1 := den1*alpha;
  (cr, c0, c1) := Modelica.Blocks.Continuous.Internal.Filter.Utilities.toHighestPowerOne(den1, den2);
""",
        why="for loops inside if-statements whose condition rumoca evaluates ('missing function value "
            "definition'): the branches read as if-expressions, alpha = 1 where not normalized",
    ),
)
