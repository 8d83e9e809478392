"""Pairing per unit (``[pairing] units``): each unit's parameter on one of its own tags, chosen on the
square relative gain array of the unit parameters.

Expectations are worked out by hand from the 2x2 relative gain ``lambda_11 = a d / (a d - b c)`` of
``[[a, b], [c, d]]`` and from the textbook fact that the relative gain array of a triangular matrix
is the identity (its inverse is triangular too, so ``A * inv(A)^T`` is diagonal, with
``a_kk / a_kk = 1`` there).
"""
from __future__ import annotations

import numpy as np
import pytest

from trackingbox.analysis.blocks import choose_block, output_unit, parameter_unit, rga_number, square_rga
from trackingbox.analysis.offsets import Residuals
from trackingbox.analysis.pair_stage import spec_units
from trackingbox.analysis.pairing import DataChecks, choose_pairs
from trackingbox.errors import SpecError
from trackingbox.spec import PairingSettings, dump_spec, loads_spec


def _pairs(p) -> dict[str, str]:
    return {x.variable: x.parameter for x in p.pairs}


def _reasons(p) -> dict[str, str]:
    return dict(p.left_out)


# Two effects of a chain. Rf1 moves its body temperature T1 (2) and its vapour pressure V1 (-1), Rf2
# moves the vapour of effect 1, which is effect 2's steam chest P2 (4, and 4.1 seen on P2's own
# transmitter). Tags T1, V1 are effect 1's, P2 effect 2's.
#          Rf1   Rf2
CHAIN = [[2.0, 1.0],    # T1  (unit 1)
         [-1.0, 4.0],   # V1  (unit 1)
         [-1.0, 4.1]]   # P2  (unit 2)
# Block T1/P2: det = 2 x 4.1 + 1 = 9.2, lambda = 8.2 / 9.2, RGA number 4 x (1 - 8.2/9.2) = 4 / 9.2.
# Block V1/P2: det = -4.1 + 4 = -0.1, lambda = 4.1 / 0.1 = 41, RGA number 4 x 40 = 160.
LAMBDA_T1 = 8.2 / 9.2


def test_square_rga_against_the_hand_formula():
    L = square_rga([[2.0, 1.0], [-1.0, 4.1]])
    assert L[0, 0] == pytest.approx(LAMBDA_T1, rel=1e-12)
    assert L[0, 1] == pytest.approx(1 - LAMBDA_T1, rel=1e-12)
    assert rga_number(L) == pytest.approx(4 / 9.2, rel=1e-12)
    assert square_rga([[1.0, 2.0], [2.0, 4.0]]) is None          # singular: no relative gain array
    # triangular: the identity, whatever the entries above the diagonal
    T = np.triu(np.arange(1.0, 17.0).reshape(4, 4))
    assert square_rga(T) == pytest.approx(np.eye(4), abs=1e-12)


def test_choose_block_takes_the_tags_whose_block_is_closest_to_the_identity():
    b = choose_block(CHAIN, {0: [0, 1], 1: [2]})
    assert (b.parameters, b.tags) == ((0, 1), (0, 2))               # Rf1 on T1, Rf2 on P2
    assert b.lambda_of(0) == pytest.approx(LAMBDA_T1, rel=1e-12)
    assert b.number == pytest.approx(4 / 9.2, rel=1e-12)
    assert b.dropped == ()
    # with V1 as Rf1's only tag the block is V1/P2 (lambda 41): valid (>= 0.1), just poor
    b = choose_block(CHAIN, {0: [1], 1: [2]})
    assert b.lambda_of(0) == pytest.approx(41.0, rel=1e-9)


def test_choose_block_leaves_out_a_parameter_no_tag_gives_a_usable_relative_gain():
    # [[1, 2], [1, 1.5]]: lambda_11 = 1 x 1.5 / (1 x 1.5 - 2 x 1) = -3 for both pairs: no valid block of
    # two. Alone each has lambda 1; the second's gain is the larger (1.5): it stays, the first is left
    # out with its relative gain beside it, -3
    b = choose_block([[1.0, 2.0], [1.0, 1.5]], {0: [0], 1: [1]})
    assert (b.parameters, b.tags) == ((1,), (1,))
    assert b.dropped == ((0, pytest.approx(-3.0, rel=1e-12)),)
    assert b.rga == pytest.approx(np.ones((1, 1)))
    assert choose_block([[1.0]], {0: []}).parameters == ()


def test_choose_block_leaves_a_parameter_unpaired_rather_than_entangle_a_pair():
    # rest() says: the pair (row 1, column 1) fails the separation check (say row 1 is the level
    # controller output of a valve that would be left unpaired). Column 1 has no other tag: it stays
    # unpaired, column 0 pairs.
    def rest(pairs):
        return 0, 0.0, int((1, 1) in pairs)

    b = choose_block([[1.0, 0.0], [0.0, 1.0]], {0: [0], 1: [1]}, rest=rest)
    assert (b.parameters, b.tags) == ((0,), (0,))
    assert b.dropped == ((1, pytest.approx(1.0)),)


def test_coordinate_descent_finds_the_triangular_block():
    # N effects of a chain (the steam chest P_k moves with the fouling of effect k and every effect
    # after it; the vapour V_k is P_{k+1} seen from effect k; the body temperature T_k moves with every
    # effect): the chest pressures form an upper-triangular block, relative gains exactly 1. 3^6 = 729
    # combinations: every one tried (exhaustive) and a descent (exhaustive=0) find the same.
    N = 6
    c = np.linspace(1.0, 2.0, N)
    P = np.triu(np.tile(c, (N, 1)))
    V = np.vstack([P[1:], np.zeros((1, N))]) + 0.05 * np.tril(np.ones((N, N)))
    T = np.full((N, N), 0.5) + np.diag(np.full(N, 0.2))
    S = np.vstack([P, V, T])                                       # rows: P_1..P_N, V_1..V_N, T_1..T_N
    cand = {k: [k, N + k, 2 * N + k] for k in range(N)}
    for exhaustive in (10_000, 0):
        b = choose_block(S, cand, exhaustive=exhaustive)
        assert b.tags == tuple(range(N))
        assert b.rga == pytest.approx(np.eye(N), abs=1e-12)


def test_unit_names():
    assert parameter_unit("effect[12].Rf", ("effect",)) == 12
    assert parameter_unit("effect[2].dBPR", ("pump",)) is None
    assert parameter_unit("inletValve.capacity", ("effect",)) is None
    assert output_unit("FI_condensate[7]") == 7
    assert output_unit("ZI_inlet") is None


def test_choose_pairs_per_unit_against_the_hand_block():
    # the chain plus a valve whose only tag is the level controller's output Z (no unit)
    G = [[2.0, 1.0, 0.0], [-1.0, 4.0, 0.0], [-1.0, 4.1, 0.0], [0.01, 0.01, 1.0]]
    V, P = ["T1", "V1", "P2", "Z"], ["effect[1].Rf", "effect[2].Rf", "valve.capacity"]
    units = ([1, 1, 2, None], [1, 2, None])
    p = choose_pairs(G, V, P, units=units)
    assert _pairs(p) == {"T1": "effect[1].Rf", "P2": "effect[2].Rf", "Z": "valve.capacity"}
    lam = {x.variable: x.lambda_ for x in p.pairs}
    # the pairs' relative gains are those of the unit block, not of the tall matrix
    assert lam["T1"] == pytest.approx(LAMBDA_T1, rel=1e-12)
    assert lam["P2"] == pytest.approx(LAMBDA_T1, rel=1e-12)
    assert p.block is not None and p.block.number == pytest.approx(4 / 9.2, rel=1e-12)
    why = _reasons(p)["V1"]
    assert "effect[1].Rf pairs with T1" in why
    assert "41" in why and "160" in why                              # the block with V1 instead, by hand


def test_per_unit_keeps_a_tag_another_parameter_needs():
    # Rf1 alone in its block (any own tag gives lambda 1): of its tags, Z1 is also the valve's only
    # one, so the block takes T1 and both pair (the most pairs first)
    G = [[1.0, 0.0], [3.0, 2.0]]
    p = choose_pairs(G, ["T1", "Z1"], ["effect[1].Rf", "valve.capacity"], units=([1, 1], [1, None]))
    assert _pairs(p) == {"T1": "effect[1].Rf", "Z1": "valve.capacity"}


def test_a_unit_parameter_without_own_tags_is_left_out_with_its_reason():
    G = [[1.0, 0.5], [0.2, 1.0]]
    p = choose_pairs(G, ["T1", "Q"], ["effect[1].Rf", "effect[2].Rf"], units=([1, None], [1, 2]))
    assert _pairs(p) == {"T1": "effect[1].Rf"}
    assert "no tracking variable belongs to its unit [2]" in _reasons(p)["effect[2].Rf"]
    # without units the whole matrix's relative gains pair both (the old rule, unchanged)
    assert _pairs(choose_pairs(G, ["T1", "Q"], ["effect[1].Rf", "effect[2].Rf"])) == {
        "T1": "effect[1].Rf", "Q": "effect[2].Rf"}


def _residuals(offsets: dict[str, float]) -> Residuals:
    rng = np.random.default_rng(1)
    n, dt = 400, 10.0
    meas = np.array([offsets[k] + rng.normal(0.0, 0.01, n) for k in offsets])
    return Residuals(tuple(offsets), dt * np.arange(n), meas, np.zeros_like(meas), dt)


def _chain_with_data(offsets: dict[str, float]):
    return choose_pairs(CHAIN, list(offsets), ["effect[1].Rf", "effect[2].Rf"], units=([1, 1, 2], [1, 2]),
                        residuals=_residuals(offsets), bounds=[(0.0, 0.0, 1.0), (0.0, 0.0, 1.0)],
                        time_constants=[[10.0, 10.0]] * 3, checks=DataChecks(noise_ratio=0.0))


def test_a_unit_tag_the_data_checks_refuse_gives_way_to_the_units_next_tag():
    # effect 1 has a second tag W1 (think: its condensate flow), moved by both: [1, 0.8].
    # Block W1/P2: det = 4.1 + 0.8 = 4.9, lambda = 4.1 / 4.9, RGA number 4 x 0.8 / 4.9 = 0.65,
    # worse than T1/P2's 0.43: without data T1 is chosen. T1's offset (-1, a bias no fouling
    # explains) needs both parameters below their lower bound 0; W1's and P2's are those of
    # Rf1 = 0.2, Rf2 = 0.1 (0.2 + 0.8 x 0.1 = 0.28; -0.2 + 4.1 x 0.1 = 0.21): W1 takes over.
    G = [CHAIN[0], CHAIN[1], [1.0, 0.8], CHAIN[2]]
    tags = ["T1", "V1", "W1", "P2"]
    units = ([1, 1, 1, 2], [1, 2])
    plain = choose_pairs(G, tags, ["effect[1].Rf", "effect[2].Rf"], units=units)
    assert _pairs(plain) == {"T1": "effect[1].Rf", "P2": "effect[2].Rf"}
    offsets = {"T1": -1.0, "V1": -0.2 + 0.4, "W1": 0.28, "P2": 0.21}
    p = choose_pairs(G, tags, ["effect[1].Rf", "effect[2].Rf"], units=units, residuals=_residuals(offsets),
                     bounds=[(0.0, 0.0, 1.0), (0.0, 0.0, 1.0)], time_constants=[[10.0, 10.0]] * 4,
                     checks=DataChecks(noise_ratio=0.0))
    assert _pairs(p) == {"W1": "effect[1].Rf", "P2": "effect[2].Rf"}
    assert {x.variable: x.lambda_ for x in p.pairs}["W1"] == pytest.approx(4.1 / 4.9, rel=1e-9)
    assert "no candidate parameter can close its offset" in _reasons(p)["T1"]


def test_a_block_the_loops_cannot_hold_together_is_refused_with_reasons():
    # the same, but P2 needs Rf2 = 9 with V1's loop holding V1 (0.1 Rf2 = 0.4 + 0.5): out of bounds,
    # the interaction lambda 41 warns of; Rf2 alone on P2 holds it (0.4 / 4.1 inside [0, 1])
    p = _chain_with_data({"T1": -1.0, "V1": -0.5, "P2": 0.4})
    assert _pairs(p) == {"P2": "effect[2].Rf"}
    why = _reasons(p)
    assert "the data checks do not allow it for effect[1].Rf" in why["V1"] and "bound" in why["V1"]
    assert "none of its unit's tags (T1, V1) is usable" in why["effect[1].Rf"]


def test_spec_units_round_trip(tmp_path):
    base = ('twin = "t.fmu"\nmeasurements = "m.csv"\nsample_time = 10.0\n[outputs]\nT = "TI_body[1]"\n'
            'Z = "ZI_body[1]"\nQ = "DI_product"\n'
            '[[parameters]]\nname = "effect[1].Rf"\nstart = 0.0\nmin = 0.0\nmax = 1.0\n'
            '[[parameters]]\nname = "valve.capacity"\nstart = 1.0\nmin = 0.5\nmax = 1.5\n')
    every = loads_spec(base + '[pairing]\nunits = ["effect"]\n', tmp_path / "s.toml", check_files=False)
    assert every.pairing.units == (("effect", ()),)
    assert spec_units(every, ["T", "Z", "Q"], ["effect[1].Rf", "valve.capacity"]) == ([1, 1, None], [1, None])
    listed = loads_spec(base + '[pairing]\nunits = { effect = ["TI_body"] }\n', tmp_path / "s.toml",
                        check_files=False)
    assert listed.pairing.units == (("effect", ("TI_body",)),)
    # the level controller's output ZI_body[1] is not listed: not a candidate of effect 1's parameters
    assert spec_units(listed, ["T", "Z", "Q"], ["effect[1].Rf", "valve.capacity"]) == ([1, None, None], [1, None])
    again = loads_spec(dump_spec(listed), tmp_path / "s.toml", check_files=False)
    assert again.pairing.units == listed.pairing.units
    assert loads_spec(base, tmp_path / "s.toml", check_files=False).pairing == PairingSettings()
    assert spec_units(loads_spec(base, tmp_path / "s.toml", check_files=False), ["T"], ["effect[1].Rf"]) is None
    for bad in ('units = "effect"', 'units = { effect = "TI_body" }', 'units = [1]'):
        with pytest.raises(SpecError, match="units must be"):
            loads_spec(base + f"[pairing]\n{bad}\n", tmp_path / "s.toml", check_files=False)


def _feed_end_case(p2_offset: float) -> dict:
    """Effect 2 upstream of effect 1's tag: P1 = Rf1 + 2 Rf2 (effect 1's steam chest sees effect 2's
    fouling through the chain), P2 = Rf2. P1 shows Rf1 = 0.5; P2 shows *p2_offset* (noise 0.01)."""
    rng = np.random.default_rng(7)
    n, dt = 600, 10.0
    meas = np.array([0.5 + rng.normal(0.0, 0.01, n), p2_offset + rng.normal(0.0, 0.01, n)])
    res = Residuals(("P1", "P2"), dt * np.arange(n), meas, np.zeros_like(meas), dt)
    return dict(gains=[[1.0, 2.0], [0.0, 1.0]], variables=["P1", "P2"], parameters=["effect[1].Rf", "effect[2].Rf"],
                residuals=res, bounds=[(0.0, 0.0, 1.0), (0.0, 0.0, 1.0)], time_constants=[[10.0, 10.0]] * 2,
                checks=DataChecks(max_leak=0.5))


def test_separation_per_unit_takes_the_move_the_data_allow():
    # P2 at its noise (RMS 0.01 < 5 x noise): effect 2 cannot be paired. Its leak into Rf1 on P1 is
    # S_pp^-1 S_pu = 2 / 1 = 2 ranges per range: the plain check (limit 0.5) refuses P1/Rf1. But had
    # Rf2 moved by m, P2 would show m (gain 1, range 1): its RMS 0.01 bounds m to ~0.01, a bias of
    # ~0.02 on Rf1, i.e. 2 x 0.01 / SEPARATION_MOVE (0.2) = 0.1 < 0.5 on the check's scale.
    kw = _feed_end_case(0.0)
    plain = choose_pairs(**kw)
    assert _pairs(plain) == {}
    assert "cannot be told apart from effect[2].Rf" in _reasons(plain)["P1"]
    units = choose_pairs(**kw, units=([1, 2], [1, 2]))
    assert _pairs(units) == {"P1": "effect[1].Rf"}
    assert "P2" in _reasons(units)["effect[2].Rf"]


def test_separation_per_unit_still_refuses_what_the_data_do_not_bound():
    # P2 shows -0.15 (needs Rf2 below its lower bound: out of reach, so effect 2 stays unpaired), which
    # bounds Rf2's move only to 0.15: weight 0.15 / 0.2 = 0.75, leak 2 x 0.75 = 1.5 > 0.5: refused
    units = choose_pairs(**_feed_end_case(-0.15), units=([1, 2], [1, 2]))
    assert _pairs(units) == {}
    why = _reasons(units)["effect[1].Rf"]
    assert "with it on P1" in why and "cannot be told apart from effect[2].Rf" in why
    assert "the data allow effect[2].Rf a move of 0.15" in why


def test_the_train_pairs_every_effects_fouling_on_its_own_thermal_tags():
    from types import SimpleNamespace

    from trackingbox.benches.evaporator_train import effect_outputs, pairing_settings, states

    n = 4
    settings = pairing_settings(n)
    (family, listed), = settings.units
    assert family == "effect"
    compensated = {s.tag for s in states(n)}
    outputs = {s.tag: s.twin for k in range(1, n + 1) for s in effect_outputs(k) if s.tag not in compensated}
    spec = SimpleNamespace(pairing=settings, outputs=outputs)
    tags = list(outputs)
    var_unit, par_unit = spec_units(spec, tags, [f"effect[{k}].Rf" for k in range(1, n + 1)] + ["outletValve.capacity"])
    assert par_unit == [1, 2, 3, 4, None]
    for tag, unit in zip(tags, var_unit):
        twin = outputs[tag]
        if twin.startswith("ZI_"):      # a level controller's output: where a valve's capacity shows
            assert unit is None, tag
        else:                           # pressures, body temperature, liquor and condensate flows
            assert unit == int(twin[twin.index("[") + 1:-1]), tag
    # five per effect: vapour and chest pressure, body temperature, liquor and condensate flow
    assert sum(u is not None for u in var_unit) == 5 * n
