"""The WSCC 3-machine 9-bus system, Anderson & Fouad variant, as a Case built from its shipped data
files (data/): `wscc9_network.json` (network, per unit on 100 MVA, 60 Hz, Anderson & Fouad bus
numbers: 1-3 generator buses, 4-9 network; with its solved load flow) and `wscc9.json` (dynamic
data: one SM4 machine file per generator, `wscc9_gen<k>.json`, Sauer-Pai two-axis data, D = 0,
Xep = Re = 0 because the transformers are network branches, and an IEEE Type I exciter each, the
IEEE1 defaults being the WSCC ones; the FMU kind a co-simulation runs for each generator).

Expected load flow: bus 2 at 9.280 deg; generator P/Q 0.7164/0.2705, 1.63/0.0665, 0.85/-0.1086.
The shipped load flow is pandapower's Newton solution of the network (`solve_load_flow`, run by
tests/test_wscc9.py, which checks it against the shipped one); running a case needs no pandapower.
pandapower's own `case9` is the MATPOWER variant (other voltages and bus numbers): not this one.
"""
from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

import numpy as np

from .case import Case, load_case, load_network

DATA_DIR = Path(__file__).resolve().parent / "data"
NETWORK_FILE = DATA_DIR / "wscc9_network.json"
DYNAMIC_DATA_FILE = DATA_DIR / "wscc9.json"


@lru_cache(maxsize=None)
def _shipped_network():
    return load_network(NETWORK_FILE)


NETWORK = _shipped_network()[0]
BUSES = NETWORK.buses
GENERATOR_BUSES = NETWORK.generator_buses


def case(dynamic_data=None) -> Case:
    """The wscc9 Case with the generators of a dynamic-data file (None: the shipped one)."""
    return _case(str(Path(dynamic_data).resolve()) if dynamic_data else str(DYNAMIC_DATA_FILE))


@lru_cache(maxsize=8)
def _case(dynamic_data: str) -> Case:
    return load_case(NETWORK_FILE, dynamic_data, "wscc9")


def load_flow():
    """The shipped load flow (case.LoadFlow)."""
    return _shipped_network()[1]


def bus_index(bus: int) -> int:
    """Row of bus number `bus` in the arrays of the case (bus order 1..9)."""
    return NETWORK.bus_index(bus)


def machine_file(bus: int) -> Path:
    """The SM4 machine file of the generator at `bus`."""
    if bus not in GENERATOR_BUSES:
        raise ValueError(f"wscc9 has generators at buses {GENERATOR_BUSES}, not {bus!r}")
    return DATA_DIR / f"wscc9_gen{bus}.json"


def pandapower_network():
    """The network as a pandapower net (bus indices = bus numbers; 230 kV network, generator buses at
    their machines' voltages; lines 1 km long with the per-unit data on the 230 kV base)."""
    import pandapower as pp

    n = NETWORK
    net = pp.create_empty_network(name="wscc9 (Anderson & Fouad)", f_hz=n.f_hz, sn_mva=n.base_mva)
    for bus in n.buses:
        pp.create_bus(net, vn_kv=n.kv[bus], name=f"bus {bus}", index=bus)
    for br in n.branches:
        if br.kind == "line":
            z_base = n.kv[br.from_bus] ** 2 / n.base_mva  # ohm
            pp.create_line_from_parameters(
                net, br.from_bus, br.to_bus, length_km=1.0, r_ohm_per_km=br.r * z_base,
                x_ohm_per_km=br.x * z_base, c_nf_per_km=br.b / z_base / (2 * math.pi * n.f_hz) * 1e9,
                max_i_ka=10.0, name=br.name)
        else:  # hv side at the network bus, lv at the generator bus; on the system base
            pp.create_transformer_from_parameters(
                net, hv_bus=br.to_bus, lv_bus=br.from_bus, sn_mva=n.base_mva, vn_hv_kv=n.kv[br.to_bus],
                vn_lv_kv=n.kv[br.from_bus], vkr_percent=100.0 * br.r, vk_percent=100.0 * abs(complex(br.r, br.x)),
                pfe_kw=0.0, i0_percent=0.0, name=br.name)
    for bus, s in n.loads.items():
        pp.create_load(net, bus, p_mw=s.real * n.base_mva, q_mvar=s.imag * n.base_mva, name=f"load {bus}")
    for g in n.generators:
        if g.kind == "slack":
            pp.create_ext_grid(net, g.bus, vm_pu=g.V, va_degree=0.0, name=f"gen {g.bus}")
        else:
            pp.create_gen(net, g.bus, p_mw=g.P * n.base_mva, vm_pu=g.V, name=f"gen {g.bus}")
    return net


def solve_load_flow(tolerance_mva: float = 1e-10) -> dict:
    """pandapower's Newton load flow of the network: V, theta [9] (pu, rad), P, Q [3] (pu) and
    pandapower's bus admittance matrix Ybus [9, 9] (no loads), bus order 1..9."""
    import pandapower as pp

    n = NETWORK
    net = pandapower_network()
    pp.runpp(net, algorithm="nr", calculate_voltage_angles=True, init="flat", tolerance_mva=tolerance_mva,
             max_iteration=50, numba=False)
    if not net.converged:
        raise RuntimeError("the wscc9 load flow did not converge")
    V = net.res_bus.loc[list(n.buses), "vm_pu"].to_numpy(float)
    theta = np.deg2rad(net.res_bus.loc[list(n.buses), "va_degree"].to_numpy(float))
    P, Q = [], []
    for g in n.generators:
        table, result = (net.ext_grid, net.res_ext_grid) if g.kind == "slack" else (net.gen, net.res_gen)
        row = table.index[table.bus == g.bus][0]
        P.append(result.at[row, "p_mw"] / n.base_mva)
        Q.append(result.at[row, "q_mvar"] / n.base_mva)
    internal, lookup = net._ppc["internal"], net._pd2ppc_lookups["bus"]
    rows = np.array([lookup[bus] for bus in n.buses])
    if np.max(np.abs(np.asarray(internal["V"])[rows] - V * np.exp(1j * theta))) > 1e-9:
        raise RuntimeError("pandapower's internal bus order does not match its bus lookup")
    Y = internal["Ybus"]
    Y = Y.toarray() if hasattr(Y, "toarray") else np.asarray(Y)
    return {"V": V, "theta": theta, "P": np.array(P), "Q": np.array(Q),
            "Ybus": np.asarray(Y[np.ix_(rows, rows)], dtype=complex)}
