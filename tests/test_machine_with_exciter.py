"""The machine FMU with an IEEE Type I exciter FMU in the loop on a prescribed bus, coupled by
cosim.bus_driven (wired by the FMUs' ports) and checked against the monolithic solve of the same
unit (reference_models.grid.monolithic.simulate_unit).

Both FMUs are the native references (SM4 of Table I, IEEE1 with the WSCC gains). The master
exchanges at the communication step h: the exciter holds the terminal voltage Vt(t_k) over the
step, the machine holds the exciter's Efd(t_k + h). Against the monolithic solve of machine +
exciter (scipy DOP853, rtol 1e-10, the same zero-order-held bus inputs) that is a coupling error of
first order in h. Measured through the dip below (Vs 1 -> 0.4 pu for 150 ms, the bus angle jumping
by 0.1 rad, 3 s): at h = 10 ms MaxAE delta 3.3e-4 rad, omega 1.54e-3 rad/s, Ed_p 3.5e-5 pu, Eq_p
1.32e-3 pu, Efd 6.9e-4 pu; at h = 2.5 ms each of them 3.98 times smaller. The test allows about 25%
above the 10 ms values and asks for a ratio within [3, 5] between 10 and 2.5 ms, which pins the
convergence of the coupling rather than a number."""
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract

from cosim.bus_driven import UnitFMU, couple, same_parameters, start_at_rest
from cosim.fmu import CouplingError
from fmu_export.native_reference_fmu import build_native_reference_fmu
from reference_models.grid.monolithic import simulate_unit
from reference_models.ieee1 import IEEE1
from reference_models.initialisation import machine_start
from reference_models.sm4 import SM4

MACHINE, EXCITER = SM4.params(), IEEE1.params()
PM = SM4.inputs[2].start
# MaxAE at h = 10 ms through the dip, about 25 % above the measured values (module docstring)
COUPLING_10MS = {"delta": 4e-4, "omega": 1.9e-3, "Ed_p": 4.5e-5, "Eq_p": 1.65e-3, "Efd": 8.5e-4}


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    """Extracted native reference FMUs: the Table I machine, the exciter, an undamped machine (D = 0)."""
    out = tmp_path_factory.mktemp("pair")
    build_native_reference_fmu(out / "SM4Reference.fmu")
    build_native_reference_fmu(out / "IEEE1Reference.fmu", "IEEE1Reference", IEEE1)
    build_native_reference_fmu(out / "Undamped.fmu", "Undamped", params={"D": 0.0})
    return {name: Path(extract(str(out / f"{name}.fmu"), unzipdir=str(out / name)))
            for name in ("SM4Reference", "IEEE1Reference", "Undamped")}


@pytest.fixture
def pair(fmus):
    return UnitFMU(fmus["SM4Reference"]), UnitFMU(fmus["IEEE1Reference"])


def monolithic(pair, times, bus, starts):
    """(machine states [T, 4], exciter states [T, 3]) of the pair solved as one ODE."""
    return simulate_unit([u.device() for u in pair], starts, times, bus)


def dip(h: float, stop: float = 3.0):
    """(times, bus [T, 3]): Vs 1 -> 0.4 pu over [0.5, 0.65) s, theta_vs 0 -> 0.1 rad from 0.5 s, Pm held."""
    times = np.arange(int(round(stop / h)) + 1) * h
    Vs = np.where((times >= 0.5 - 1e-12) & (times < 0.65 - 1e-12), 0.4, 1.0)
    theta = np.where(times >= 0.5 - 1e-12, 0.1, 0.0)
    return times, np.stack([Vs, theta, np.full_like(times, PM)], axis=1)


def test_the_fmus_parameters_are_read_from_the_fmus(pair):
    machine, exciter = pair
    assert machine.params == MACHINE and exciter.params == EXCITER


@pytest.mark.parametrize("point", ["table I", "load flow"])
def test_the_pair_started_at_its_initial_point_stays_at_rest(pair, point):
    machine, exciter = pair
    if point == "table I":  # the equilibrium at Vs = 1, theta_vs = 0 with Table I's Pm and Efd
        x0, u0, Efd = SM4.steady_state(None, MACHINE), (1.0, 0.0, PM), SM4.inputs[3].start
    else:  # a load-flow point: 1.02 pu at 0.3 rad, P = 0.8, Q = 0.25 (Pm and Efd from the initialisation)
        start = machine_start(1.02, 0.3, 0.8, 0.25, MACHINE)
        x0, u0, Efd = start.x0, (1.02, 0.3, start.Pm), start.Efd
    start = start_at_rest(pair, x0, u0, {"Efd": Efd})
    times = np.arange(201) * 0.01
    run = couple(pair, times, np.tile(u0, (len(times), 1)), start)
    np.testing.assert_allclose(run.machine, np.tile(x0, (len(times), 1)), rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.states[1], np.tile(start[1].states, (len(times), 1)), rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.terminal_voltage, start[1].inputs["Vt"], rtol=0, atol=1e-9)


def coupling_error(pair, h: float) -> dict:
    """MaxAE of the pair coupled at h against the monolithic solve, through the dip; and Efd's peak."""
    times, bus = dip(h)
    start = start_at_rest(pair, SM4.steady_state(None, MACHINE), bus[0], {"Efd": SM4.inputs[3].start})
    run = couple(pair, times, bus, start)
    x, xe = monolithic(pair, times, bus, start)
    errors = dict(zip(SM4.state_names, np.abs(run.machine - x).max(axis=0)))
    return errors | {"Efd": np.abs(run.states[1][:, 0] - xe[:, 0]).max(), "peak": xe[:, 0].max()}


def test_through_a_dip_the_pair_follows_the_monolithic_solve_to_a_coupling_error_first_order_in_h(pair):
    coarse, fine = coupling_error(pair, 0.01), coupling_error(pair, 0.0025)
    assert coarse["peak"] > SM4.inputs[3].start + 1.0  # the exciter forced the field up in the dip
    for name, limit in COUPLING_10MS.items():
        assert coarse[name] <= limit, (name, coarse[name])
        assert 3.0 <= coarse[name] / fine[name] <= 5.0, (name, coarse[name], fine[name])


def test_the_master_refuses_fmus_in_the_wrong_role(fmus):
    machine, exciter = UnitFMU(fmus["SM4Reference"]), UnitFMU(fmus["IEEE1Reference"])
    times, bus = dip(0.01, 0.1)
    start = start_at_rest((machine, exciter), SM4.steady_state(None, MACHINE), bus[0], {"Efd": 1.08})
    with pytest.raises(CouplingError, match="IEEE1Reference declares no bus port: the unit's first FMU must be its machine"):
        couple((exciter, machine), times, bus, start)
    with pytest.raises(CouplingError, match="only the machine may have a bus port"):
        couple((machine, machine), times, bus, start)


def test_the_master_refuses_a_pair_of_different_machines(fmus):
    damped, undamped = UnitFMU(fmus["SM4Reference"]), UnitFMU(fmus["Undamped"])
    with pytest.raises(CouplingError, match=r"SM4Reference and Undamped model different sm4 parameters: D 2.0 / 0.0"):
        same_parameters(damped, undamped)


def test_bad_bus_inputs_are_refused(pair):
    times, bus = dip(0.01, 0.1)
    start = start_at_rest(pair, SM4.steady_state(None, MACHINE), bus[0], {"Efd": 1.08})
    bad = bus.copy()
    bad[3, 0] = np.nan
    with pytest.raises(CouplingError, match="must be finite"):
        couple(pair, times, bad, start)
    with pytest.raises(CouplingError, match="must start at 0 and increase"):
        couple(pair, times[::-1], bus, start)


def test_a_surrogate_fmu_in_the_loop_takes_its_machine_from_its_operator_and_stays_at_rest(fmu_path, fmus):
    """The shipped operator's surrogate FMU (conftest's fmu_path) coupled the same way: its machine is
    the one its operator records (the reference's), at rest it stays there (its rest correction) and
    inside its envelope."""
    surrogate, exciter = UnitFMU(fmu_path), UnitFMU(fmus["IEEE1Reference"])
    same_parameters(surrogate, UnitFMU(fmus["SM4Reference"]))
    x0 = SM4.steady_state(None, MACHINE)
    start = start_at_rest((surrogate, exciter), x0, (1.0, 0.0, PM), {"Efd": SM4.inputs[3].start})
    times = np.arange(201) * 0.01
    run = couple((surrogate, exciter), times, np.tile((1.0, 0.0, PM), (len(times), 1)), start)
    assert run.in_envelope is True and run.max_residual is not None
    np.testing.assert_allclose(run.machine, np.tile(x0, (len(times), 1)), rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.states[1], np.tile(start[1].states, (len(times), 1)), rtol=0, atol=1e-9)
