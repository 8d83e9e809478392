"""Choosing tracking pairs: step tests, relative gain array, Sobol sensitivity.

* :mod:`~trackingbox.analysis.rga` -- ``relative_gain_array``, ``condition_number``, scaling helpers.
* :mod:`~trackingbox.analysis.steptest` -- steady-state gain matrix of the twin by parameter
  steps with its controllers frozen.
* :mod:`~trackingbox.analysis.pairing` -- one parameter per tracking variable by RGA (``choose_pairs``).
* :mod:`~trackingbox.analysis.sobol` -- Sobol indices over the parameter bounds and their
  agreement with the RGA pairing.
* :mod:`~trackingbox.analysis.executor` -- local process pool or Dask cluster for the runs.

SALib (the Sobol method) and Dask (``--scheduler``) load only when a run needs them.
"""
