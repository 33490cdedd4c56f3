"""SUBSYSTEM: a whole sub-system (a feeder of inverters, a plant) seen through its boundary bus, the
component its learned operator is an operator of (issue 35, docs/subsystems.md).

States  x = (theta_f, theta_w [rad]: the boundary's frequency measurement, ANDES' BusFreq, network
        frame; Ip, Iq [pu, system base]: the active and reactive current the sub-system's devices
        deliver at the boundary, in the frame of the boundary voltage, > 0 generating; n [1]: the
        boundary's load-flow voltage over the sub-system's own, V0 / V_own); a sub-system with a plant
        controller (SUBSYSTEM_PC, `subsystem_pc`) carries four more: Qpi, Qcmd, Ppi, Pcmd [pu, system
        base], its REPCA1's reactive PI integrator (s2_xi) and command lag (s3_x), active PI
        integrator (s5_xi) and command lag (s6_y), each summed over the plant's REPCA1
Inputs  u = (Vs [pu], theta_vs [rad]: the boundary bus voltage)
Outputs y = (I_re, I_im [pu, system base]: the current injected into the boundary bus, network
        frame; P, Q [pu, system base]: the power injected, generator convention; f [pu]: the
        measured boundary frequency)

What is known is written here; what is not is learned:
    the sub-system's boundary transformer has settled its tap to keep its inside at the voltages of
    the sub-system's own load flow (an on-load tap changer before the study:
    reference_models.grid.attach), so the inside sees the boundary voltage divided by about
    n = V0 / V_own, a constant of the study (dn/dt = 0);
    the network's passive part (lines, transformers and constant-impedance loads with every device's
    current taken out, Kron-reduced onto the boundary at the sub-system's own voltage: G + jB [pu,
    system base]) then draws
        I_passive = -(G + jB) V / n^2,
    the devices deliver I_dev = (Ip - j Iq) e^{j theta_vs}, so that
        I = I_dev + I_passive,  P = Ip Vs - G Vs^2 / n^2,  Q = Iq Vs + B Vs^2 / n^2;
    the boundary frequency is what a BusFreq at the boundary measures (blocks.bus_frequency):
        busf_Tf dtheta_f/dt = theta_vs - theta_f,  busf_Tw dtheta_w/dt = theta_f - theta_w;
    Ip and Iq follow the devices' controls, trips and limits, hundreds of states that the sub-system's
    operator replaces: their rate is learned (`learned_states`), written here as 0;
    a plant controller acts on every unit at once through states of seconds (its PI integrators) and
    its command lags (50-150 ms, most of a window): these few plant-wide states are what two boundary
    currents do not tell, so SUBSYSTEM_PC carries them where asked (`--carry-controller`), learned
    too (0 at any start, where ANDES' REPCA1 starts them; nothing holds their learned rates at 0 at
    rest: docs/subsystems.md); its measurement filters (20-50 ms) follow the boundary voltage the
    operator reads, and the units' own states are too many and too fast to carry.

A deep fault acts on the passive part exactly (its admittance is the Norton admittance of the port)
and on the devices through the operator. The state is rotation invariant but not speed invariant
(the devices' frequency droops and trips read the speed): the drift frame only turns.

Parameters: the system base Sb and the sub-system's rating S [MVA] (the sum of its generating
devices' Sn); G, B; the boundary voltage V_own [pu] of the sub-system's own load flow and the
devices' currents Ip_own, Iq_own there (its rest: the learned rates have none of their own); the measurement's busf_Tf, busf_Tw [s], busf_fn [Hz]
(the sub-system's own BusFreq settings). An operator of it is trained for one sub-system: its FMU
holds them fixed.

Start from the load flow (V0, theta0, P0, Q0 at the boundary): theta_f = theta_w = theta0,
n = V0 / V_own, Ip = (P0 + G V0^2 / n^2) / V0, Iq = (Q0 - B V0^2 / n^2) / V0.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..blocks import bus_frequency, lags_of_ramp
from ..component import Component, Initialisation, Parameters, Quantity
from ..drift import Drift
from ..ports import BusPort, Ports
from .common import check_ranges, finite_inputs

PARAMETER_RANGES = {
    "Sb": (1e-3, 1e5, "MVA"), "S": (1e-6, 1e6, "MVA"), "G": (-1e4, 1e4, "pu"), "B": (-1e4, 1e4, "pu"),
    "V_own": (0.5, 1.5, "pu"), "Ip_own": (-1e4, 1e4, "pu"), "Iq_own": (-1e4, 1e4, "pu"),
    "busf_Tf": (0.0, 10.0, "s"), "busf_Tw": (1e-3, 10.0, "s"), "busf_fn": (16.0, 400.0, "Hz"),
}


@dataclass(frozen=True)
class SubsystemParams(Parameters):
    """A sub-system at its boundary (module docstring): bases Sb, S [MVA]; passive admittance G, B
    [pu, system base]; its own boundary voltage V_own [pu] and the devices' currents there Ip_own, Iq_own
    [pu, system base]; the boundary
    measurement busf_Tf, busf_Tw [s], busf_fn [Hz]."""

    Sb: float = 100.0
    S: float = 10.0
    G: float = 0.0
    B: float = 0.0
    V_own: float = 1.0
    Ip_own: float = 0.0
    Iq_own: float = 0.0
    busf_Tf: float = 0.02
    busf_Tw: float = 0.1
    busf_fn: float = 60.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)


# the plant controllers' states a sub-system with them carries (SUBSYSTEM_PC), summed over its REPCA1
# (each a share of one plant controller: their sums are the plant's): the reactive PI's integrator and
# its command lag, the active PI's integrator and its command lag [pu, system base]
PLANT_CONTROLLER_STATES = (("Qpi", "s2_xi", "plant controllers' reactive PI integrators"),
                           ("Qcmd", "s3_x", "plant controllers' reactive commands beyond the units' own (lag state)"),
                           ("Ppi", "s5_xi", "plant controllers' active PI integrators"),
                           ("Pcmd", "s6_y", "plant controllers' active commands beyond the units' own (lag)"))
N_BOUNDARY = 5  # theta_f, theta_w, Ip, Iq, n: the states of every sub-system


def derivatives(x, u, p: SubsystemParams, m):
    """(dtheta_f, dtheta_w, dIp, dIq, dn, then any carried controller's)/dt: the measurement's; the
    devices' currents' and the controllers' are learned (0); n is a constant of the study."""
    d_f, d_w, _ = bus_frequency(m, u[1], x[0], x[1], p.busf_Tf, p.busf_Tw, p.busf_fn)
    return (d_f, d_w, 0.0 * x[2], 0.0 * x[3], 0.0 * x[4], *(0.0 * x[k] for k in range(N_BOUNDARY, len(x))))


def start_equations(x, u, p: SubsystemParams, m):
    """The start's residuals: the measurement at rest, the tap settled to the load flow's boundary
    voltage (n V_own = Vs), a carried controller's states at 0 (its PI integrators and command lags
    start there, ANDES' REPCA1); the learned currents' rows are unread (the load flow's P, Q fix them)."""
    d_f, d_w, _ = bus_frequency(m, u[1], x[0], x[1], p.busf_Tf, p.busf_Tw, p.busf_fn)
    return (d_f, d_w, 0.0 * x[2], 0.0 * x[3], x[4] * p.V_own - u[0], *(x[k] for k in range(N_BOUNDARY, len(x))))


def outputs(x, u, p: SubsystemParams, m):
    """(I_re, I_im, P, Q) [pu, system base], f [pu]."""
    Ip, Iq = x[2], x[3]
    Vs, theta = u[0], u[1]
    c, s = m.cos(theta), m.sin(theta)
    f = bus_frequency(m, theta, x[0], x[1], p.busf_Tf, p.busf_Tw, p.busf_fn)[2]
    G, B = p.G / (x[4] * x[4]), p.B / (x[4] * x[4])  # the passive part through the settled tap
    V_re, V_im = Vs * c, Vs * s
    I_re = Ip * c + Iq * s - (G * V_re - B * V_im)
    I_im = Ip * s - Iq * c - (G * V_im + B * V_re)
    return I_re, I_im, Ip * Vs - G * Vs * Vs, Iq * Vs + B * Vs * Vs, f


def _equilibrium(carried: int):
    def equilibrium(u, p: SubsystemParams) -> np.ndarray:
        """The rest [5 + carried] under constant (Vs, theta_vs), as if the load flow had put the
        boundary at Vs: the measurement at theta_vs, n = Vs / V_own, the devices delivering the power
        of the sub-system's own load flow (Ip_own V_own, Iq_own V_own) through the settled tap, a
        carried controller at its start (0)."""
        Vs, theta = (float(v) for v in finite_inputs(u, "SUBSYSTEM")[:2])
        if not Vs > 0.0:
            raise ValueError(f"SUBSYSTEM: no rest at a boundary voltage of {Vs:.6g} pu")
        n = Vs / p.V_own
        return np.array([theta, theta, p.Ip_own / n, p.Iq_own / n, n] + [0.0] * carried)
    return equilibrium


def measured_frequency_map(p: SubsystemParams, sensor_times, n_x: int) -> np.ndarray:
    """A [S, n_x + 2 S]: the measured boundary frequency's deviation [Hz] at each sensor time of a
    window as a linear function of the window's x0 (its theta_f, theta_w: states 0, 1) and its sensors
    (Vs, theta_vs) flattened time-major, exact for a boundary angle linear between sensors: the
    measurement (blocks.lags_of_ramp) stepped on rows of coefficients, f - fn = (theta_f - theta_w) /
    (2 pi busf_Tw) (busf_Tf = 0: the angle passes). A common rotation of every angle leaves it
    unchanged, so it reads a window's frame as well."""
    t = np.asarray(sensor_times, float)
    n_v = n_x + 2 * t.size
    angle = np.zeros((t.size, n_v))  # theta_vs at each sensor as a row over (x0, sensors)
    angle[np.arange(t.size), n_x + 2 * np.arange(t.size) + 1] = 1.0
    filtered, washed = (np.eye(n_v)[0] if p.busf_Tf > 0.0 else angle[0]), np.eye(n_v)[1]
    out = np.zeros((t.size, n_v))
    out[0] = filtered - washed
    for j in range(1, t.size):
        filtered, washed = lags_of_ramp(filtered, washed, angle[j - 1], angle[j], t[j] - t[j - 1], p.busf_Tf, p.busf_Tw)
        out[j] = filtered - washed
    return out / (2.0 * math.pi * p.busf_Tw)


def _starter(carried: int):
    def start(given, p: SubsystemParams) -> tuple:
        V0, theta0, P0, Q0 = (float(given[k]) for k in ("V0", "theta0", "P0", "Q0"))
        if not (math.isfinite(V0) and V0 > 0.0):
            raise ValueError(f"SUBSYSTEM: no start at a boundary voltage of {V0:.6g} pu")
        n = V0 / p.V_own
        return np.array([theta0, theta0, (P0 + p.G * V0 * V0 / n ** 2) / V0, (Q0 - p.B * V0 * V0 / n ** 2) / V0, n]
                        + [0.0] * carried), {}
    return start


BOUNDARY_STATES = (
    Quantity("theta_f", "rad", "boundary angle through the measurement's filter (BusFreq)"),
    Quantity("theta_w", "rad", "washout state of the boundary's frequency measurement (BusFreq)"),
    Quantity("Ip", "pu", "devices' active current at the boundary, voltage frame (system base)"),
    Quantity("Iq", "pu", "devices' reactive current at the boundary, voltage frame (system base; > 0 "
             "delivers reactive power)"),
    Quantity("n", "1", "boundary load-flow voltage over the sub-system's own (V0 / V_own)"))

BOUNDARY_INPUTS = (
    Quantity("Vs", "pu", "boundary bus voltage magnitude", start=1.0, operating_range=(0.0, 1.2), minimum=0.0),
    Quantity("theta_vs", "rad", "boundary bus voltage angle", start=0.0, operating_range=(-0.5, 0.5)))
BOUNDARY_OUTPUTS = (
    Quantity("I_re", "pu", "current injected into the boundary bus, real part (network frame, system base)"),
    Quantity("I_im", "pu", "current injected into the boundary bus, imaginary part (network frame, system base)"),
    Quantity("P", "pu", "active power injected into the boundary bus (system base)"),
    Quantity("Q", "pu", "reactive power injected into the boundary bus (system base)"),
    Quantity("f", "pu", "measured boundary frequency (1: nominal)"))


def _subsystem(name: str, description: str, carried: tuple) -> Component:
    """The sub-system component with the boundary's states and the learned states `carried`
    (Quantity, each 0 at the start)."""
    extra = tuple(range(N_BOUNDARY, N_BOUNDARY + len(carried)))
    return Component(
        name=name,
        description=description,
        states=BOUNDARY_STATES + carried,
        inputs=BOUNDARY_INPUTS,
        outputs=BOUNDARY_OUTPUTS,
        params_type=SubsystemParams,
        derivatives=derivatives,
        output_equations=outputs,
        equilibrium=_equilibrium(len(carried)),
        state_scales=(0.1, 0.1, 0.05, 0.05, 0.05) + (0.05,) * len(carried),
        # busf_Tf dtheta_f/dt = theta_vs - theta_f, busf_Tw dtheta_w/dt = theta_f - theta_w, dn/dt = 0
        affine_states=(0, 1, 4),
        drift=Drift(angle_states=(0, 1), angle_inputs=(1,), speed_state=None),
        ports=Ports(bus=BusPort(voltage=("Vs", "theta_vs"), current=("I_re", "I_im"))),
        initialisation=Initialisation((), _starter(len(carried))),
        learned_states=(2, 3) + extra,
        started_learned=extra,
        start_equations=start_equations,
        window_features=lambda p, sensor_times: measured_frequency_map(p, sensor_times, N_BOUNDARY + len(carried)),
    )


SUBSYSTEM = _subsystem("subsystem", "a sub-system seen through its boundary bus: passive network and measurement "
                       "known, devices learned", ())
SUBSYSTEM_PC = _subsystem("subsystem_pc", "a sub-system with a plant controller seen through its boundary bus: "
                          "passive network and measurement known, devices and the controller's states learned",
                          tuple(Quantity(n, "pu", f"{what} (sum over its REPCA1, system base)")
                                for n, _, what in PLANT_CONTROLLER_STATES))
