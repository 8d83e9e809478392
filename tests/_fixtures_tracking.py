"""A first-order "heat exchanger" twin made with CasADi, and plant cases for tracking tests.

Model: ``dx/dt = (u - x)/tau - k·x``, ``y = x``, ``tau = 100 s``, tunable ``k``.
Steady state ``x = u/(1 + k·tau)``: with ``u = 50`` the plant (``k = 0.004``)
sits at ``50/1.4 = 35.714`` and the untracked twin (``k = 0.003``) at
``50/1.3 = 38.462``. ``dx/dk = -u·tau/(1 + k·tau)^2 = -2551`` at the plant's
operating point; the response time constant is ``1/(1/tau + k) = 71 s``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from _fixtures_casadi import build_casadi_fmu, rewrite_model_description
from trackingbox.compiler.fmi_export import declare_fixed

from trackingbox.testing.specs import first_order_spec

TAU = 100.0
K_PLANT = 0.004
K_TWIN = 0.003


def make_first_order_fmu(directory: Path, variability: str = "tunable") -> Path:
    """Export, compile and pack the model as an FMI 3.0 model-exchange FMU in *directory*.

    *variability* ``"fixed"`` declares ``k`` fixed in the model description, as other tools export
    parameters (the compiler's ``--parameters fixed``). CasADi's own ``"fixed"`` variability is not
    used: its FMU then keeps the start value whatever is set before initialisation.
    """
    fmu = build_casadi_fmu(directory, "hx1", constants={"TAU": TAU}, variables=[
        ("k", ("parameter", "tunable"), {"start": K_TWIN, "min": 0.0, "max": 0.1}),
        ("u", ("input",), {"start": 50.0}),
        ("x", ("local", "continuous"), {"start": 38.0, "initial": "exact"}),
        ("y", ("output",), {}),
    ], equations=[("der(x)", "(u - x) / TAU - k * x"), ("y", "x")])
    if variability == "fixed":
        rewrite_model_description(fmu, lambda xml: declare_fixed(xml, {"k"}))
    return fmu


def spec_text(k_twin: float, data: str = "", controller: str = "pi") -> str:
    """The case's spec: *data* is TOML placed after the windows (a ``[data]`` section)."""
    return first_order_spec(start=k_twin, lower=0.001, upper=0.01, training=(0.0, 3000.0),
                            validation=(3000.0, 6000.0), extra=data, hold_until=200.0,
                            pair={"gain": -2551.0, "time_constant": 71.0, "lambda": 1.0, "controller": controller})


def plant_input(t: np.ndarray) -> np.ndarray:
    """The scenario's input: 50, a step to 60 at 2000 s, to 55 at 4000 s."""
    return 50.0 + 10.0 * (t > 2000.0) - 5.0 * (t > 4000.0)




def make_case(fmu: Path, out: Path, *, k_plant: float = K_PLANT, noise: float = 0.02, seed: int = 1,
              stop: float = 6000.0, nan_span: tuple[float, float] | None = None,
              stoppage: tuple[float, float] | None = None, settle: float = 100.0,
              controller: str = "pi", max_gap: float | None = None) -> Path:
    """Simulate the plant (``k = k_plant``), add noise, write measurements + spec; return the spec path."""
    from trackingbox.fmu import FMUModel

    out.mkdir(parents=True, exist_ok=True)
    t = np.arange(0.0, stop + 1.0, 10.0)
    u = plant_input(t)
    if stoppage is not None:
        u = np.where((t >= stoppage[0]) & (t < stoppage[1]), 0.0, u)
    with FMUModel(fmu) as m:
        sim = m.simulate(stop_time=stop, output_interval=10.0, inputs=pd.DataFrame({"time": t, "u": u}),
                         parameters={"k": k_plant, "x": 50.0 / (1.0 + k_plant * TAU)}, outputs=["y"])
    rng = np.random.default_rng(seed)
    y = sim["y"].to_numpy() + rng.normal(0.0, noise, t.size)
    if nan_span is not None:
        y[(t >= nan_span[0]) & (t < nan_span[1])] = np.nan
    pd.DataFrame({"time": t, "FI": u, "TI": y, "TI_true": sim["y"].to_numpy()}).to_csv(
        out / "measurements.csv", index=False, na_rep="")
    (out / "twin.fmu").write_bytes(Path(fmu).read_bytes())
    rules = []
    if stoppage is not None:
        rules.append(f'stoppage = {{ tag = "FI", below = 1.0, settle = {settle} }}')
    if max_gap is not None:
        rules.append(f"max_gap = {max_gap}")
    data = "\n[data]\n" + "\n".join(rules) + "\n" if rules else ""
    spec = out / "spec.toml"
    spec.write_text(spec_text(K_TWIN, data, controller), encoding="utf-8")
    return spec


def make_tank_fmu(directory: Path, *, leak: float) -> Path:
    """The first-order model plus an open tank with a correction-flow input.

    ``d(level)/dt = (q - leak·level + m_corr)/200`` (200 kg per m of level), ``q``
    an input (kg/s), ``m_corr`` the state-compensation input, ``leak`` fixed
    (the plant's differs from the twin's).
    """
    return build_casadi_fmu(directory, "tank1", constants={"TAU": TAU, "leak": leak}, variables=[
        ("k", ("parameter", "tunable"), {"start": K_TWIN, "min": 0.0, "max": 0.1}),
        ("u", ("input",), {"start": 50.0}),
        ("q", ("input",), {"start": 1.0}),
        ("m_corr", ("input",), {"start": 0.0}),
        ("x", ("local", "continuous"), {"start": 38.0, "initial": "exact"}),
        ("h", ("local", "continuous"), {"start": 1.0, "initial": "exact"}),
        ("y", ("output",), {}),
        ("level", ("output",), {}),
    ], equations=[("der(x)", "(u - x) / TAU - k * x"), ("der(h)", "(q - leak * h + m_corr) / 200.0"),
                  ("y", "x"), ("level", "h")])


#: spec of the tank case (:func:`make_tank_fmu`): TI -> k paired, LI compensated through m_corr
TANK_SPEC = '''twin = "twin.fmu"
measurements = "measurements.csv"
sample_time = 10.0
[inputs]
"FI" = "u"
"QI" = "q"
[outputs]
"TI" = "y"
[[parameters]]
name = "k"
start = 0.003
min = 0.001
max = 0.01
[[pairs]]
variable = "TI"
parameter = "k"
gain = -2551.0
time_constant = 71.0
lambda = 1.0
[[states]]
tag = "LI"
variable = "level"
correction = "m_corr"
gain = 5.0
'''


def native_unavailable() -> str | None:
    """Why the native stepper cannot be built or loaded here (None: it can): the reason of a skip."""
    from trackingbox import native

    try:
        native.library()
    except native.NativeUnavailable as exc:
        return str(exc)
    return None
