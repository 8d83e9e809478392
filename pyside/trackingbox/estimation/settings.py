"""The estimation's defaults, budgets and tolerances (one place for the numbers its modules share)."""
from __future__ import annotations

from collections.abc import Callable

#: Default number of differential-evolution generations for a small problem; see
#: :func:`default_maxiter` for the budget that applies to many parameters.
DEFAULT_MAXITER = 30
#: Default budget of the global search in simulations (coarse grid): the default number of
#: generations is the most that keeps ``population * (generations + 1)`` within it.
DEFAULT_GLOBAL_EVALUATIONS = 480
#: Default population of differential evolution, in all (not per parameter): scipy's usual
#: 15 per parameter is unaffordable when one simulation takes seconds and there are a dozen
#: parameters; the refinement does the fine work. The population is ``max(2, ceil(15 / n))``
#: per parameter: 15 for one parameter, 28 for fourteen.
DEFAULT_POPULATION = 15
#: Grid step of the global search's cost (s): the training window is simulated and scored on
#: the largest multiple of ``sample_time`` not above this (inputs averaged over it), which makes
#: each of its many simulations several times cheaper. The refinement and the reported NRMSE
#: always use the full ``sample_time`` grid.
DEFAULT_GLOBAL_GRID = 60.0
#: The global search stops once the better half of its population (by coarse cost) lies within
#: this fraction of every parameter's bound range: the population agrees on one basin, and the
#: refinement (Gauss-Newton steps on the exact Jacobian) walks the rest of the way in a few runs,
#: where differential evolution would spend a population's worth of runs per generation
#: contracting onto the same point. Not the best point's movement: a best point that no trial
#: beat for a few generations may still be far from the minimum. 0 (``settle=0``): run every
#: generation.
GLOBAL_SETTLE = 0.1
#: Cost returned for a parameter set whose simulation fails (NRMSE units; a fit is << 1).
FAILED_COST = 1.0e3
#: Finite-difference step of the refinement's Jacobian, as a fraction of each parameter's
#: bound range (not of its value: a pipe coefficient near its lower bound would otherwise get
#: a step lost in solver noise). Forward differences, taken backwards at the upper bound.
DIFF_STEP = 1.0e-3

#: How the refinement's Jacobian is computed: ``"exact"`` (sensitivity equations from the FMU's
#: directional derivatives, one run for residuals and Jacobian), ``"fd"`` (forward differences,
#: ``1 + n`` runs), ``"auto"`` (the default: fd where the twin's runs are native, see
#: :func:`jacobian_support`; else exact where the twin supports it, else fd),
#: ``"prefer-exact"`` (exact where the twin supports it, else fd: for a caller that wants the
#: more accurate refinement whatever it costs, such as diagnosis's null model).
JACOBIAN_METHODS = ("auto", "exact", "fd", "prefer-exact")

#: The refinement stops when the next Gauss-Newton step (from the Jacobian at the accepted point,
#: projected on the bounds) moves no parameter by more than this fraction of its bound range. The
#: twin's cost carries the integrator's noise (about 1e-4 of its value at rtol 1e-6 near the
#: optimum), so least squares' own ``ftol`` of 1e-6 is met only by chance there, and the steps it
#: keeps taking (measured on the heat-exchanger bench: 2e-6 to 1.5e-5 of the range) move nothing
#: that matters: the statistical uncertainty of an estimate is orders of magnitude above.
REFINE_STEP_TOLERANCE = 1.0e-5

#: Refinement budget per pass: least-squares iterations (each costs 1 + n_parameters simulations,
#: the n of the Jacobian in parallel over the workers).
MAX_REFINE_ITERATIONS = 20

#: ``progress(stage, iteration, total, cost)``: stage ``"global"`` after each generation (best mean NRMSE),
#: ``"refine"`` after each refinement simulation (root mean square of the tags' NRMSE at that point, the
#: budget as total), ``"local"`` once when the refinement is done (best mean NRMSE).
ProgressCallback = Callable[[str, int, int, float], None]
