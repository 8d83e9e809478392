"""Small test cases for the estimation tests: a first-order heat-exchanger FMU and synthetic data.

The model (built with CasADi's FMI 3 exporter, no Modelica needed) is one
well-mixed water volume heated by a stream and losing heat to the ambient::

    C dT/dt = m_flow * cp * (T_in - T) - kht * A * (T - T_amb)

with ``C = 2e5 J/K``, ``cp = 4186 J/(kg K)``, ``T_amb = 15 degC``; the twin's own
start value ``T = 20 degC`` is far from the data's initial state, so the
warm-up matters. ``kht`` (W/(m2 K)) is the parameter to estimate, ``A`` (m2) is
known. Data are made by simulating the "plant" at a known ``kht`` from steady
state and adding Gaussian noise.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from _fixtures_casadi import build_casadi_fmu

CP = 4186.0
C_TH = 2.0e5
T_AMB = 15.0
AREA = 2.0


def build_fmu(directory: Path) -> Path:
    """Compile the first-order heat-exchanger FMU into *directory*; return its path."""
    return build_casadi_fmu(directory, "hx1", constants={"CP": CP, "C_TH": C_TH, "T_AMB": T_AMB}, variables=[
        ("kht", ("parameter", "tunable"), {"start": 1000.0, "min": 100.0, "max": 5000.0}),
        ("A", ("parameter", "tunable"), {"start": 1.0}),
        ("m_flow", ("input",), {"start": 0.5}),
        ("T_in", ("input",), {"start": 80.0}),
        ("T", ("local", "continuous"), {"start": 20.0, "initial": "exact"}),
        ("T_out", ("output",), {}),
    ], equations=[("der(T)", "(m_flow * CP * (T_in - T) - kht * A * (T - T_AMB)) / C_TH"), ("T_out", "T")])


def steady_state(m_flow: float, t_in: float, kht: float) -> float:
    """Hand-solved steady state of the model: dT/dt = 0."""
    return (m_flow * CP * t_in + kht * AREA * T_AMB) / (m_flow * CP + kht * AREA)


def inputs(t: np.ndarray, *, stoppage: tuple[float, float] | None = None) -> pd.DataFrame:
    """Excitation: flow with sines and steps, inlet temperature with a slow sine."""
    m = 0.45 + 0.2 * np.sin(t / 700.0) + 0.1 * (np.sin(t / 1900.0) > 0)
    if stoppage is not None:
        m = np.where((t >= stoppage[0]) & (t < stoppage[1]), 0.0, m)
    tin = 80.0 + 5.0 * np.sin(t / 1300.0)
    return pd.DataFrame({"time": t, "m_flow": m, "T_in": tin})


def plant_data(fmu: Path, kht: float, *, hours: float = 4.0, dt: float = 10.0, noise: float = 0.1,
               seed: int = 1, stoppage: tuple[float, float] | None = None) -> pd.DataFrame:
    """Measurements of the plant: starts from the steady state of the first inputs, noisy outlet.

    Columns ``time``, ``FI-1`` (flow), ``TI-0`` (inlet temperature), ``TI-1``
    (outlet temperature, with N(0, noise^2) noise).
    """
    from trackingbox.fmu import FMUModel

    t = np.arange(0.0, hours * 3600.0 + dt / 2, dt)
    u = inputs(t, stoppage=stoppage)
    model = FMUModel(fmu)
    try:
        # the twin starts at 20 degC: run a long pre-run at the first inputs so the plant starts settled
        pre = 20000.0
        u_pre = pd.concat([u.iloc[:1].assign(time=0.0), u.assign(time=u["time"] + pre)], ignore_index=True)
        r = model.simulate(stop_time=pre + t[-1], output_interval=dt, inputs=u_pre,
                           parameters={"kht": kht, "A": AREA}, outputs=["T_out"])
    finally:
        model.close()
    y = np.interp(pre + t, r["time"], r["T_out"])
    rng = np.random.default_rng(seed)
    y = y + rng.normal(0.0, noise, t.size)
    return pd.DataFrame({"time": t, "FI-1": u["m_flow"], "TI-0": u["T_in"], "TI-1": y})


SPEC = """\
# test spec: first-order heat exchanger
twin = "hx1.fmu"
measurements = "{measurements}"
sample_time = 10.0

[inputs]
"FI-1" = "m_flow"
"TI-0" = "T_in"

[outputs]
"TI-1" = "T_out"

[[parameters]]
name = "{name}"   # heat-transfer coefficient
start = {start}
min = {min}
max = {max}

[fixed]
A = 2.0

[windows]
training = [{train0}, {train1}]
validation = [{valid0}, {valid1}]
{data}"""


def write_case(directory: Path, fmu: Path, table: pd.DataFrame, *, name: str = "kht", start: float = 1000.0,
               lo: float = 600.0, hi: float = 1400.0, training: tuple[float, float] = (0.0, 7200.0),
               validation: tuple[float, float] = (7200.0, 14400.0), data: str = "",
               measurements: str = "measurements.csv", initial: str | None = "steady") -> Path:
    """Write measurements CSV + spec.toml (and a copy of the FMU) into *directory*; return the spec path.

    *initial*: the spec's ``[data] initial`` (default ``"steady"``: the plant of :func:`plant_data`
    starts settled at its first inputs, and so does the twin); None leaves it out.
    """
    import shutil

    if initial is not None:
        line = f'initial = "{initial}"'
        data = data.replace("[data]\n", f"[data]\n{line}\n", 1) if "[data]\n" in data else \
            data + f"\n[data]\n{line}\n"

    directory.mkdir(parents=True, exist_ok=True)
    if not (directory / "hx1.fmu").exists():
        shutil.copy(fmu, directory / "hx1.fmu")
    table.to_csv(directory / measurements, index=False)
    text = SPEC.format(measurements=measurements, name=name, start=start, min=lo, max=hi,
                       train0=training[0], train1=training[1], valid0=validation[0], valid1=validation[1],
                       data=data)
    spec = directory / "spec.toml"
    spec.write_text(text, encoding="utf-8")
    return spec
