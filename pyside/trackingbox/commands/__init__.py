"""The ``trackingbox`` subcommands, one module each (``register(subparsers)``, ``run(args)``).

:data:`SUMMARIES` is each command's one-line help, in the order ``trackingbox --help`` lists them.
It lives here, apart from the commands' modules, so that the command line can list every command
while importing only the one that runs (a command's module imports its whole stage).
"""
from __future__ import annotations

SUMMARIES: dict[str, str] = {
    "compile": "compile a Modelica class into an FMU",
    "inspect": "list an FMU's variables (causality, variability, start, bounds, unit)",
    "simulate": "simulate an FMU with an inputs table and parameter values, write the outputs to CSV",
    "bench": "generate a bench case: plant and twin FMUs, noisy measurements, spec.toml",
    "pair": "pair tracking variables with tracking parameters (step tests + RGA, or Sobol)",
    "identify": "what the data can determine of the spec's [[parameters]] (rank, undetermined combinations, "
                "correlation)",
    "estimate": "estimate the spec's [[parameters]] from the measurements (training/validation windows)",
    "track": "run the tracking simulator (parameter controllers) over the measurements",
    "replay": "serve a bench case's measurements over OPC UA (a simulated DCS for the online mode)",
    "view": "serve the live web view of a tracking run's output folder",
    "generate": "generate the Modelica tracking box and tracked model (gen-trackingbox)",
    "validate": "run the tracked FMU on the validation window; compare with the twin and the Python runtime",
    "diagnose": "find where the twin and the measurements disagree and name the missing effect",
    "config": "list the TRACKINGBOX_* settings: value, source (default/env), what each does",
}
