"""The simulation service every stage uses: a model cache (:mod:`.models`) and window runs (:mod:`.windows`).

A stage never opens an FMU or reaches into another stage for one: it takes a cached
model (:func:`~.models.cached_model`) or one of its own (:func:`~.models.open_model`), and
runs the twin over a window of the measurements with :func:`~.windows.simulate_window`.
"""
