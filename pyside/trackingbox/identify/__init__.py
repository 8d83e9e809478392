"""What the data determine: identifiability, confidence intervals and bands on tracked parameters.

* :mod:`~trackingbox.identify.structure` -- numerics of a scaled sensitivity matrix: rank,
  undetermined directions, the products/ratios or sums the data do determine, correlation.
* :mod:`~trackingbox.identify.model` -- the twin on the estimation's window: residuals and
  output sensitivities (exact from the FMU's directional derivatives, or central differences).
* :mod:`~trackingbox.identify.analysis` -- ``trackingbox identify``: the analysis at the start
  values and at points inside the bounds, in words; pairing's candidate check.
* :mod:`~trackingbox.identify.noise` -- the residuals' long-run covariance and integral time scale.
* :mod:`~trackingbox.identify.intervals` -- intervals at an estimate: sandwich covariance with the
  residuals' autocorrelation, profile likelihood where the linearisation is poor.
* :mod:`~trackingbox.identify.bands` -- the band of each tracked parameter, row by row.
* :mod:`~trackingbox.identify.held` -- the bands' fixed part: what the parameters the twin holds at an
  estimate may be off by, through each pair's tag (step tests at track start).
* :mod:`~trackingbox.identify.thermal` -- the MSL thermal-wall case (two resistors, a capacitor).
* :mod:`~trackingbox.identify.hooks` -- what estimation, pairing and tracking call.
"""
