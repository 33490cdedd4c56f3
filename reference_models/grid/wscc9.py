"""The WSCC 3-machine 9-bus system, Anderson & Fouad variant: network data, load flow, admittance
matrix and the dynamic data of its generators.

Per unit on 100 MVA, 60 Hz, Anderson & Fouad bus numbers (1-3 generator buses, 4-9 network).
The network is built as a pandapower net (`pandapower_network`), whose Newton load flow gives the
operating point and whose internal bus admittance matrix is the one the dynamics use
(`load_flow().Ybus`, checked against `assemble_ybus`, which builds it from the data below).
pandapower's own `case9` is the MATPOWER variant (other voltages and bus numbers): not this one.

Expected load flow: bus 2 at 9.280 deg; generator P/Q 0.7164/0.2705, 1.63/0.0665, 0.85/-0.1086.

Dynamic data (`dynamic_data`): one SM4 machine file per generator (`data/wscc9_gen<k>.json`, the
format of `SM4.load_params`; Sauer-Pai two-axis data, D = 0, Xep = Re = 0 because the transformers
are network branches, so the machine's Vs is its generator bus) and an IEEE Type I exciter each
(the IEEE1 defaults are the WSCC ones), listed in `data/wscc9.json`.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..ieee1 import IEEE1, IEEE1Params
from ..sm4 import SM4, SM4Params

BASE_MVA = 100.0
F_HZ = 60.0
BUSES = tuple(range(1, 10))
GENERATOR_BUSES = (1, 2, 3)
NOMINAL_KV = {1: 16.5, 2: 18.0, 3: 13.8}  # generator buses; the network buses are 230 kV
NETWORK_KV = 230.0
DATA_DIR = Path(__file__).resolve().parent / "data"
DYNAMIC_DATA_FILE = DATA_DIR / "wscc9.json"


@dataclass(frozen=True)
class Branch:
    """A pi branch between two buses: series R + jX and total shunt susceptance B [pu]."""

    from_bus: int
    to_bus: int
    r: float
    x: float
    b: float
    kind: str  # "line" or "transformer"

    @property
    def name(self) -> str:
        return f"{self.from_bus}-{self.to_bus}"

    def connects(self, bus: int) -> bool:
        return bus in (self.from_bus, self.to_bus)


LINES = (
    Branch(4, 5, 0.010, 0.085, 0.176, "line"),
    Branch(4, 6, 0.017, 0.092, 0.158, "line"),
    Branch(5, 7, 0.032, 0.161, 0.306, "line"),
    Branch(6, 9, 0.039, 0.170, 0.358, "line"),
    Branch(7, 8, 0.0085, 0.072, 0.149, "line"),
    Branch(8, 9, 0.0119, 0.1008, 0.209, "line"),
)
TRANSFORMERS = (
    Branch(1, 4, 0.0, 0.0576, 0.0, "transformer"),
    Branch(2, 7, 0.0, 0.0625, 0.0, "transformer"),
    Branch(3, 9, 0.0, 0.0586, 0.0, "transformer"),
)
BRANCHES = LINES + TRANSFORMERS
LOADS = {5: complex(1.25, 0.50), 6: complex(0.90, 0.30), 8: complex(1.00, 0.35)}  # P + jQ [pu]


@dataclass(frozen=True)
class GeneratorData:
    """A generator in the load flow: the slack (V, angle 0) or a PV bus (P, V) [pu]."""

    bus: int
    kind: str  # "slack" or "pv"
    V: float
    P: float | None = None


GENERATORS = (
    GeneratorData(1, "slack", 1.04),
    GeneratorData(2, "pv", 1.025, 1.63),
    GeneratorData(3, "pv", 1.025, 0.85),
)


def bus_index(bus: int) -> int:
    """Row of bus number `bus` in the arrays of this module (bus order 1..9)."""
    if bus not in BUSES:
        raise ValueError(f"wscc9 has no bus {bus!r} (buses {BUSES[0]}..{BUSES[-1]})")
    return BUSES.index(bus)


def branch(name) -> Branch:
    """The branch named "a-b" (or given as a pair (a, b)), in either order."""
    if isinstance(name, Branch):
        return name
    try:
        a, b = (int(v) for v in (name.split("-") if isinstance(name, str) else name))
    except (ValueError, TypeError):
        raise ValueError(f"a branch is named FROM-TO, e.g. 5-7; got {name!r}") from None
    for br in BRANCHES:
        if {a, b} == {br.from_bus, br.to_bus}:
            return br
    raise ValueError(f"wscc9 has no branch {a}-{b} (branches: {', '.join(br.name for br in BRANCHES)})")


def connected_buses(out_of_service=()) -> set:
    """The buses connected to bus 1 with the given branches open."""
    removed = {branch(b) for b in out_of_service}
    reach, frontier = {1}, [1]
    while frontier:
        bus = frontier.pop()
        for br in BRANCHES:
            if br in removed or not br.connects(bus):
                continue
            other = br.to_bus if br.from_bus == bus else br.from_bus
            if other not in reach:
                reach.add(other)
                frontier.append(other)
    return reach


def disconnects_generator(trip) -> bool:
    """Whether opening branch `trip` leaves a generator bus cut off from the others."""
    return not set(GENERATOR_BUSES) <= connected_buses([trip])


def openable(name) -> Branch:
    """The branch named `name` (see `branch`), refused with a ValueError naming the branches that may
    open instead when opening it would cut a generator off."""
    br = branch(name)
    if disconnects_generator(br):
        raise ValueError(f"opening branch {br.name} disconnects a generator (branches that may open at its "
                         f"buses: {', '.join(trips_at(br.from_bus))}; {', '.join(trips_at(br.to_bus))})")
    return br


def trips_at(bus: int) -> tuple:
    """The branches at `bus` whose opening keeps every generator connected (names "a-b")."""
    bus_index(bus)
    return tuple(br.name for br in BRANCHES if br.connects(bus) and not disconnects_generator(br))


def assemble_ybus(out_of_service=()) -> np.ndarray:
    """The bus admittance matrix [9, 9] (complex, pu, bus order 1..9) assembled from the branch data,
    without loads; `out_of_service`: branches left out."""
    removed = {branch(b) for b in out_of_service}
    Y = np.zeros((len(BUSES), len(BUSES)), dtype=complex)
    for br in BRANCHES:
        if br in removed:
            continue
        i, k = bus_index(br.from_bus), bus_index(br.to_bus)
        y = 1.0 / complex(br.r, br.x)
        Y[i, i] += y + 0.5j * br.b
        Y[k, k] += y + 0.5j * br.b
        Y[i, k] -= y
        Y[k, i] -= y
    return Y


def pandapower_network():
    """The system as a pandapower net (bus indices = bus numbers; 230 kV network, generator buses at
    their machines' voltages; lines 1 km long with the per-unit data on the 230 kV base)."""
    import pandapower as pp

    net = pp.create_empty_network(name="wscc9 (Anderson & Fouad)", f_hz=F_HZ, sn_mva=BASE_MVA)
    for bus in BUSES:
        pp.create_bus(net, vn_kv=NOMINAL_KV.get(bus, NETWORK_KV), name=f"bus {bus}", index=bus)
    z_base = NETWORK_KV ** 2 / BASE_MVA  # ohm
    for br in LINES:
        pp.create_line_from_parameters(
            net, br.from_bus, br.to_bus, length_km=1.0, r_ohm_per_km=br.r * z_base,
            x_ohm_per_km=br.x * z_base, c_nf_per_km=br.b / z_base / (2 * math.pi * F_HZ) * 1e9,
            max_i_ka=10.0, name=br.name)
    for br in TRANSFORMERS:  # hv side at the network bus, lv at the generator bus; on 100 MVA
        pp.create_transformer_from_parameters(
            net, hv_bus=br.to_bus, lv_bus=br.from_bus, sn_mva=BASE_MVA, vn_hv_kv=NETWORK_KV,
            vn_lv_kv=NOMINAL_KV[br.from_bus], vkr_percent=100.0 * br.r, vk_percent=100.0 * abs(complex(br.r, br.x)),
            pfe_kw=0.0, i0_percent=0.0, name=br.name)
    for bus, s in LOADS.items():
        pp.create_load(net, bus, p_mw=s.real * BASE_MVA, q_mvar=s.imag * BASE_MVA, name=f"load {bus}")
    for g in GENERATORS:
        if g.kind == "slack":
            pp.create_ext_grid(net, g.bus, vm_pu=g.V, va_degree=0.0, name=f"gen {g.bus}")
        else:
            pp.create_gen(net, g.bus, p_mw=g.P * BASE_MVA, vm_pu=g.V, name=f"gen {g.bus}")
    return net


@dataclass(frozen=True)
class LoadFlow:
    """The load-flow solution (arrays in bus order 1..9, generators in GENERATOR_BUSES order, pu, rad).

    V, theta: bus voltage magnitudes and angles; P_gen, Q_gen: generator injections; S_load: the
    loads' P + jQ at every bus (0 where none); Ybus: pandapower's bus admittance matrix (no loads)."""

    V: np.ndarray
    theta: np.ndarray
    P_gen: np.ndarray
    Q_gen: np.ndarray
    S_load: np.ndarray
    Ybus: np.ndarray

    @property
    def V_complex(self) -> np.ndarray:
        return self.V * np.exp(1j * self.theta)

    def load_admittances(self) -> np.ndarray:
        """The constant-impedance loads [9] (complex, pu) drawing S_load at the load-flow voltages."""
        return np.conj(self.S_load) / self.V ** 2

    def generator(self, bus: int) -> dict:
        """V, theta, P, Q of the generator at `bus`."""
        k, i = GENERATOR_BUSES.index(bus), bus_index(bus)
        return {"V": float(self.V[i]), "theta": float(self.theta[i]),
                "P": float(self.P_gen[k]), "Q": float(self.Q_gen[k])}


_LOAD_FLOW: LoadFlow | None = None


def load_flow(tolerance_mva: float = 1e-10) -> LoadFlow:
    """pandapower's Newton load flow of the system (computed once per process at the default
    tolerance; the arrays are read-only)."""
    global _LOAD_FLOW
    if _LOAD_FLOW is not None and tolerance_mva == 1e-10:
        return _LOAD_FLOW
    import pandapower as pp

    net = pandapower_network()
    pp.runpp(net, algorithm="nr", calculate_voltage_angles=True, init="flat", tolerance_mva=tolerance_mva,
             max_iteration=50, numba=False)
    if not net.converged:
        raise RuntimeError("the wscc9 load flow did not converge")
    V = net.res_bus.loc[list(BUSES), "vm_pu"].to_numpy(float)
    theta = np.deg2rad(net.res_bus.loc[list(BUSES), "va_degree"].to_numpy(float))
    P, Q = [], []
    for bus in GENERATOR_BUSES:
        table, result = (net.ext_grid, net.res_ext_grid) if bus == 1 else (net.gen, net.res_gen)
        row = table.index[table.bus == bus][0]
        P.append(result.at[row, "p_mw"] / BASE_MVA)
        Q.append(result.at[row, "q_mvar"] / BASE_MVA)
    S_load = np.zeros(len(BUSES), dtype=complex)
    for bus, s in LOADS.items():
        S_load[bus_index(bus)] = s
    result = LoadFlow(V=V, theta=theta, P_gen=np.array(P), Q_gen=np.array(Q), S_load=S_load,
                      Ybus=_pandapower_ybus(net, V * np.exp(1j * theta)))
    for a in (result.V, result.theta, result.P_gen, result.Q_gen, result.S_load, result.Ybus):
        a.setflags(write=False)
    if tolerance_mva == 1e-10:
        _LOAD_FLOW = result
    return result


def _pandapower_ybus(net, V_expected) -> np.ndarray:
    """pandapower's internal Ybus [9, 9] in bus order 1..9 (pu on net.sn_mva = 100 MVA, which is the
    system base, so no rescaling). Internal rows follow net._pd2ppc_lookups["bus"]; the internal
    voltage vector is checked to land on res_bus in that order."""
    internal = net._ppc["internal"]
    lookup = net._pd2ppc_lookups["bus"]
    rows = np.array([lookup[bus] for bus in BUSES])
    if float(net.sn_mva) != BASE_MVA:
        raise RuntimeError(f"pandapower per-unit base {net.sn_mva} MVA, expected {BASE_MVA}")
    V_internal = np.asarray(internal["V"])[rows]
    if np.max(np.abs(V_internal - V_expected)) > 1e-9:
        raise RuntimeError("pandapower's internal bus order does not match its bus lookup")
    Y = internal["Ybus"]
    Y = Y.toarray() if hasattr(Y, "toarray") else np.asarray(Y)
    return np.asarray(Y[np.ix_(rows, rows)], dtype=complex)


FMU_KINDS = ("surrogate", "reference", "python", "file")


@dataclass(frozen=True)
class GeneratorFMU:
    """Which FMUs a co-simulation runs for a generator: `kind` surrogate (the machine's operator
    file `operator`, an IEEE1 native reference exciter), reference (native reference machine and
    exciter), python (pythonfmu reference machine and exciter) or file (the FMU files `machine_fmu`
    and `exciter_fmu` as they are). Paths are resolved against the dynamic-data file's folder; an
    operator not found there is looked up among the shipped ones by the grid layer."""

    kind: str = "reference"
    operator: str | None = None
    machine_fmu: str | None = None
    exciter_fmu: str | None = None


@dataclass(frozen=True)
class GeneratorDynamics:
    """A generator's dynamic data: its bus, SM4 machine parameters (and the file they came from),
    IEEE1 exciter parameters and the FMUs a co-simulation runs for it."""

    bus: int
    machine: SM4Params
    exciter: IEEE1Params
    machine_file: Path
    fmu: GeneratorFMU = GeneratorFMU()


def machine_file(bus: int) -> Path:
    """The SM4 machine file of the generator at `bus` (`SM4.load_params` format)."""
    if bus not in GENERATOR_BUSES:
        raise ValueError(f"wscc9 has generators at buses {GENERATOR_BUSES}, not {bus!r}")
    return DATA_DIR / f"wscc9_gen{bus}.json"


def _generator_fmu(path: Path, generator: dict) -> GeneratorFMU:
    """The `fmu` entry of a generator in the dynamic-data file at `path` (default: native reference)."""
    entry = generator.get("fmu", {"kind": "reference"})
    entry = {"kind": entry} if isinstance(entry, str) else entry
    if not isinstance(entry, dict) or entry.get("kind") not in FMU_KINDS:
        raise ValueError(f"{path}: generator at bus {generator.get('bus')}: fmu kind must be one of "
                         f"{', '.join(FMU_KINDS)}, got {str(entry)[:60]!r}")
    unknown = set(entry) - {"kind", "operator", "machine_fmu", "exciter_fmu"}
    if unknown:
        raise ValueError(f"{path}: generator at bus {generator.get('bus')}: unknown fmu keys {', '.join(sorted(unknown))}")

    def resolved(key):
        value = entry.get(key)
        if value is None:
            return None
        if not isinstance(value, str) or not value:
            raise ValueError(f"{path}: generator at bus {generator.get('bus')}: fmu {key} must be a file name")
        beside = path.parent / value
        return str(beside) if beside.exists() or key != "operator" else value

    fmu = GeneratorFMU(kind=entry["kind"], operator=resolved("operator"), machine_fmu=resolved("machine_fmu"),
                       exciter_fmu=resolved("exciter_fmu"))
    if fmu.kind == "surrogate" and fmu.operator is None:
        raise ValueError(f"{path}: generator at bus {generator.get('bus')}: a surrogate needs its operator file")
    if fmu.kind == "file" and (fmu.machine_fmu is None or fmu.exciter_fmu is None):
        raise ValueError(f"{path}: generator at bus {generator.get('bus')}: kind file needs machine_fmu and exciter_fmu")
    return fmu


def dynamic_data(path=DYNAMIC_DATA_FILE) -> tuple:
    """The GeneratorDynamics of every generator, in GENERATOR_BUSES order, from the dynamic-data file
    (machine files are resolved beside it)."""
    path = Path(path)
    data = json.loads(path.read_text(encoding="utf-8"))
    by_bus = {}
    for g in data["generators"]:
        machine, exciter = g["machine"], g["exciter"]
        if machine.get("component") != SM4.name or exciter.get("component") != IEEE1.name:
            raise ValueError(f"{path}: generator at bus {g['bus']}: only sm4 machines with ieee1 exciters are modelled")
        file = path.parent / machine["file"]
        by_bus[int(g["bus"])] = GeneratorDynamics(bus=int(g["bus"]), machine=SM4.load_params(file),
                                                  exciter=IEEE1.params(exciter.get("params", {})), machine_file=file,
                                                  fmu=_generator_fmu(path, g))
    if sorted(by_bus) != list(GENERATOR_BUSES):
        raise ValueError(f"{path}: needs one generator at each of the buses {GENERATOR_BUSES}, got {sorted(by_bus)}")
    return tuple(by_bus[bus] for bus in GENERATOR_BUSES)
