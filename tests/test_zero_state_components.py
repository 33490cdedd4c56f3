"""A component without states (reference_models.component: n_x = 0, its outputs a function of its
inputs alone), on the ZIP load (reference_models.models.zip): empty rates and states of the right
shape, the same outputs on numpy, torch and the generated C, a start from the load flow that
refuses a point it cannot draw, no operator to learn; its native reference FMUs (FMI 2.0 and 3.0)
build and validate with no state variables, give the ZIP functions' current over a voltage sweep,
advance time and inputs without integrating, give exact directional derivatives, restore and
serialize their FMU state, and survive random FMI calls and corrupt serialized states."""
from __future__ import annotations

import ctypes
import json
import subprocess
from dataclasses import replace

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.validation import validate_fmu

from cosim.fmu import FMU as Slave, CouplingError
from fmu_export.binaries import fmi_headers
from fmu_export.build_cache import cached_native_reference_fmu
from fmu_export.c_equations import equations_c_source
from fmu_export.variables import BUS_OUTPUTS, fmu_ports
from reference_models.models import STANDARD_MODELS
from reference_models.models.zip import ZIP, ZIPParams, zip_current, zip_power
from reference_models.ports import ports_of_fmu

PERCENTAGES = {"kpp": 30.0, "kpi": 30.0, "kpz": 40.0, "kqp": 10.0, "kqi": 20.0, "kqz": 70.0}
POINT = {"P0": -0.8, "Q0": 0.1, "V0": 0.97}  # the load-flow point the sweeps hold
H = 0.01  # s: the communication step
TESTS = __file__.rsplit("/", 1)[0]


ANDES_TIMES = (1.05, 2.5)  # s: mid-fault (bus 4, 1.0-1.1 s) and after clearing


def _p():
    return ZIP.params(PERCENTAGES)


def _function_params():
    """The ZIP functions' parameters of the same load: the percentages with the load-flow point."""
    return ZIPParams(**PERCENTAGES, **POINT)


def _inputs(V, theta):
    return np.array([V, theta, POINT["P0"], POINT["Q0"], POINT["V0"]])


def _sweep():
    """(V, theta) pairs from a deep dip to an overvoltage, at angles around the circle."""
    return list(zip(np.linspace(0.2, 1.3, 23), np.linspace(-3.0, 3.0, 23)))


@pytest.fixture(scope="module")
def zip_fmus(fmu_cache):
    """{FMI version: path} of the ZIP's native reference FMU (host platform, PERCENTAGES, its inputs
    starting at POINT)."""
    return {v: cached_native_reference_fmu("ZIPReference", ZIP, PERCENTAGES, operating_point=dict(POINT),
                                           fmi_version=v, cache=fmu_cache) for v in (2, 3)}


# --- the component ------------------------------------------------------------------------------

def test_zip_is_a_registered_component_without_states():
    assert STANDARD_MODELS["ZIP"] is ZIP
    assert ZIP.n_states == 0 and ZIP.state_names == () and ZIP.initialisation.solves == ()
    assert ZIP.ports.bus.voltage == ("Vs", "theta_vs") and ZIP.ports.bus.current == ("I_re", "I_im")


def test_a_component_without_states_gives_empty_rates_and_states_of_the_batch_shape():
    torch = pytest.importorskip("torch")
    p = _p()
    u = ZIP.start_inputs
    x = ZIP.steady_state(u, p)
    assert x.shape == (0,) and ZIP.rhs(x, u, p).shape == (0,) and ZIP.output_values(x, u, p).shape == (4,)
    us = np.array([_inputs(V, theta) for V, theta in _sweep()])
    for xs in (np.zeros((len(us), 0)), np.zeros(0)):  # a batch of (empty) states, or one broadcast
        assert ZIP.rhs(xs, us, p).shape == (len(us), 0)
        assert ZIP.output_values(xs, us, p).shape == (len(us), 4)
    assert ZIP.output_values(np.zeros((3, 0)), us[0], p).shape == (3, 4)  # one input row for a batch of states
    t = torch.tensor(us)
    assert tuple(ZIP.rhs(torch.zeros(len(us), 0, dtype=torch.float64), t, p).shape) == (len(us), 0)
    np.testing.assert_allclose(ZIP.output_values(torch.zeros(len(us), 0, dtype=torch.float64), t, p).numpy(),
                               ZIP.output_values(np.zeros((len(us), 0)), us, p), rtol=1e-15, atol=0)


def test_the_component_gives_the_zip_functions_current_and_power():
    p, f = _p(), _function_params()
    for V, theta in _sweep():
        got = ZIP.output_values(np.zeros(0), _inputs(V, theta), p)
        want = (*zip_current(V, theta, f), *zip_power(V, f))
        np.testing.assert_allclose(got, want, rtol=1e-14, atol=1e-15)


def test_numpy_torch_and_generated_c_outputs_agree(tmp_path):
    torch = pytest.importorskip("torch")
    p = _p()
    source, library = tmp_path / "equations.c", tmp_path / "equations.so"
    source.write_text(equations_c_source(ZIP, p, linkage=""))
    subprocess.run(["gcc", "-O2", "-std=c99", "-Wall", "-Werror", "-shared", "-fPIC", str(source), "-o", str(library),
                    "-lm"], check=True)
    outputs = ctypes.CDLL(str(library)).model_outputs
    pointer = ctypes.POINTER(ctypes.c_double)
    rng = np.random.default_rng(3)
    low, high = np.array([q.operating_range for q in ZIP.inputs]).T
    us = low + (high - low) * rng.random((200, ZIP.n_inputs))
    by_numpy = ZIP.output_values(np.zeros((200, 0)), us, p)
    by_torch = ZIP.output_values(torch.zeros(200, 0, dtype=torch.float64), torch.tensor(us), p).numpy()
    by_c = np.empty_like(by_numpy)
    x = np.zeros(1)  # the one unused state C declares
    for row, u in zip(by_c, us):
        u, out = np.ascontiguousarray(u), np.empty(4)
        outputs(x.ctypes.data_as(pointer), u.ctypes.data_as(pointer), out.ctypes.data_as(pointer))
        row[:] = out
    np.testing.assert_allclose(by_torch, by_numpy, rtol=1e-15, atol=1e-15)
    np.testing.assert_allclose(by_c, by_numpy, rtol=1e-14, atol=1e-15)


def test_the_start_takes_the_load_flow_point_and_injects_it_there():
    p = _p()
    given = {"Vs": 1.02, "theta_vs": -0.3, "V0": 1.02, "theta0": -0.3, "P0": -0.45, "Q0": -0.12}
    x0, inputs = ZIP.start(given, p)
    assert x0.shape == (0,)
    assert inputs == {"Vs": 1.02, "theta_vs": -0.3, "P0": -0.45, "Q0": -0.12, "V0": 1.02}
    _, _, P, Q = ZIP.output_values(x0, np.array([inputs[n] for n in ZIP.input_names]), p)
    assert (P, Q) == (pytest.approx(-0.45, rel=1e-15), pytest.approx(-0.12, rel=1e-15))


def test_the_start_refuses_a_load_flow_point_the_zip_cannot_draw():
    given = {"Vs": 1.0, "theta_vs": 0.0, "V0": 1.0, "theta0": 0.0, "P0": -0.5, "Q0": -0.1}
    with pytest.raises(ValueError, match="ZIP: parameter P0 = -0.5 must be 0 where kpp \\+ kpi \\+ kpz = 0"):
        ZIP.start(given, ZIP.params({"kpp": 0.0, "kpi": 0.0, "kpz": 0.0}))
    with pytest.raises(ValueError, match="ZIP: at the bus voltage Vs = 0.9 pu it injects"):
        ZIP.start({**given, "Vs": 0.9}, _p())  # its bus voltage is not the load flow's
    with pytest.raises(ValueError, match="no start without the input\\(s\\) V0"):
        ZIP.start({k: v for k, v in given.items() if k != "V0"}, _p())


def test_a_component_without_states_has_no_operator_to_learn():
    from surrogate.data.presets import preset

    with pytest.raises(ValueError, match="the zip component has no states: a component without states has no "
                                         "operator to learn"):
        ZIP.require_states()
    with pytest.raises(ValueError, match="preset 'cosim': the zip component has no states"):
        replace(preset("cosim"), component="zip", levels={})
    STANDARD_MODELS["GENROU"].require_states()  # one with states: nothing to refuse


# --- its native reference FMUs ------------------------------------------------------------------

@pytest.mark.parametrize("version", [2, 3])
def test_the_fmus_validate_with_no_state_variables_and_carry_the_bus_port(zip_fmus, version):
    path = zip_fmus[version]
    assert validate_fmu(str(path)) == []
    assert ports_of_fmu(path) == fmu_ports(ZIP)
    md = read_model_description(str(path))
    outputs = [v.name for v in md.modelVariables if v.causality == "output"]
    assert outputs == ["I_re", "I_im", "P", "Q", *(name for name, _ in BUS_OUTPUTS)]
    # the solver's tolerances, then the model's own parameters (one FMU serves every ZIP)
    assert [v.name for v in md.modelVariables if v.causality == "parameter"] == ["rtol", "atol",
                                                                               *ZIP.params_type().to_dict()]
    assert [v.name for v in md.modelVariables if v.causality == "input"] == list(ZIP.input_names)
    depends = {u.variable.name: {v.name for v in u.dependencies} for u in md.outputs}
    assert depends == {"I_re": set(ZIP.input_names), "I_im": set(ZIP.input_names), "P": {"Vs", "P0", "V0"},
                       "Q": {"Vs", "Q0", "V0"}, **{name: set(ZIP.input_names) for name, _ in BUS_OUTPUTS}}


@pytest.mark.parametrize("version", [2, 3])
def test_the_fmu_gives_the_zip_functions_current_over_a_voltage_sweep(zip_fmus, version):
    f = _function_params()
    slave = Slave(zip_fmus[version], component=ZIP)
    got, want = [], []
    for V, theta in _sweep():
        assert slave.step(H, V, theta).shape == (0,)
        got.append(slave.get("I_re", "I_im", "P", "Q"))
        want.append((*zip_current(V, theta, f), *zip_power(V, f)))
    slave.close()
    np.testing.assert_allclose(got, want, rtol=1e-14, atol=1e-15)


def test_a_step_advances_time_and_ramped_inputs_without_integrating(zip_fmus):
    """FMI 2.0 with input derivatives: after a step of h from t with Vs rising at 2 pu/s, the FMU is
    at t + h with Vs + 2 h and gives the current there; a step from the old time is refused."""
    f = _function_params()
    slave = Slave(zip_fmus[2], component=ZIP)
    slave.bind(ZIP.input_names, ("Vs", "I_re", "I_im"))
    slave.set_inputs(list(_inputs(0.9, 0.4)))
    slave.set_input_derivatives([2.0, 0.0, 0.0, 0.0, 0.0])
    slave.do_step(0.0, 0.05)
    Vs, I_re, I_im = slave.outputs()
    assert Vs == pytest.approx(1.0, rel=1e-15)
    np.testing.assert_allclose((I_re, I_im), zip_current(Vs, 0.4, f), rtol=1e-14)
    with pytest.raises(CouplingError, match="is not the FMU's time"):
        slave.do_step(0.0, 0.05)
    slave.close()


@pytest.mark.parametrize("version", [2, 3])
def test_the_fmu_directional_derivatives_are_the_exact_jacobian(zip_fmus, version):
    torch = pytest.importorskip("torch")
    p = _p()
    slave = Slave(zip_fmus[version], component=ZIP)
    slave.bind(ZIP.input_names, ZIP.output_names)
    for V, theta in _sweep()[::4]:
        u = _inputs(V, theta)
        slave.set_inputs(list(u))
        got = np.array(slave.output_jacobian(range(4), range(ZIP.n_inputs)))
        want = torch.autograd.functional.jacobian(
            lambda v: ZIP.output_values(torch.zeros(0, dtype=torch.float64), v, p), torch.tensor(u)).numpy()
        np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-14)
    slave.close()


@pytest.mark.parametrize("version", [2, 3])
def test_the_fmu_state_is_restored_and_serialized(zip_fmus, version):
    """Outputs and time after setting a saved state, and after deserializing its bytes into a new
    state, are those it was saved at."""
    slave = Slave(zip_fmus[version], component=ZIP)
    slave.bind(ZIP.input_names, ZIP.output_names)
    slave.set_inputs(list(_inputs(0.8, 0.2)))
    slave.do_step(0.0, H)
    saved, at = slave.save(), slave.outputs()
    fmu = slave.fmu
    data = bytes(fmu.serializeFMUstate(saved) if version == 2 else fmu.serializeFMUState(saved))
    slave.set_inputs(list(_inputs(0.5, -1.0)))
    slave.do_step(H, H)
    assert slave.outputs() != at
    slave.restore(saved)
    assert slave.outputs() == at
    slave.do_step(H, H)  # at the saved time again
    restored = fmu.deSerializeFMUstate(data) if version == 2 else fmu.deserializeFMUState(data)
    slave.restore(restored)
    assert slave.outputs() == at
    slave.do_step(H, H)
    slave.free(saved)
    slave.free(restored)
    slave.close()


def _compile(tmp_path, source: str):
    program = tmp_path / source.rsplit(".", 1)[0]
    subprocess.run(["gcc", "-O1", "-I", str(fmi_headers()), f"{TESTS}/c/{source}", "-o", str(program), "-ldl", "-lm"],
                   check=True)
    return program


def test_random_fmi_call_sequences_and_corrupt_states_never_crash_it(zip_fmus, tmp_path):
    """The C importers' random FMI calls (tests/c/fuzz_harness.c) and broken serialized states
    (tests/c/state_fuzz.c, the rtol parameter as the probe) on the FMI 2.0 FMU: every call returns a
    valid status, every refused state leaves the instance as it was."""
    directory = extract(str(zip_fmus[2]), unzipdir=str(tmp_path / "fmu"))
    md = read_model_description(directory)
    binary = f"{directory}/binaries/linux64/{md.coSimulation.modelIdentifier}.so"
    n_reals = sum(v.type == "Real" for v in md.modelVariables)
    result = subprocess.run([str(_compile(tmp_path, "fuzz_harness.c")), binary, md.guid, "3000", "1", str(n_reals)],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr[-2000:]
    counts = dict(zip(result.stdout.split()[0::2], map(int, result.stdout.split()[1::2])))
    assert counts["steps"] > 500 and counts["error"] > 300 and counts["invalid"] == counts["bad_messages"] == 0
    rtol = next(v for v in md.modelVariables if v.name == "rtol")
    result = subprocess.run([str(_compile(tmp_path, "state_fuzz.c")), binary, md.guid, "5", "0", str(n_reals),
                             str(rtol.valueReference), repr(1.2345678e-7)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr[-2000:]


# --- against ANDES ------------------------------------------------------------------------------

@pytest.mark.andes
def test_the_grid_case_starts_the_zip_at_its_load_flow_and_it_draws_andes_power_through_a_fault(tmp_path):
    """ieee14_zip.json with its ZIP's percentages made to sum to 100 (50 % P, 40 % I, 10 % Z of its
    PQ's P; 100 % P of its Q) and without its generator trip (with it, ANDES' TDS stops converging at
    1.016 s under this fault): the case conversion gives the ZIP its percentages and a start at its
    PQ's load-flow power and ANDES' bus voltage; at ANDES' bus voltage mid-fault and after clearing its
    current carries ANDES' power drawn."""
    andes = pytest.importorskip("andes")
    from reference_models.grid.andes_case import case_from_file, configure_andes_logging

    configure_andes_logging(andes, 40)
    data = json.loads(open(andes.get_case("ieee14/ieee14_zip.json")).read())
    data["ZIP"][0]["kpz"] = 10.0
    del data["Toggler"]
    path = tmp_path / "ieee14_zip100.json"
    path.write_text(json.dumps(data))
    case = case_from_file(path, cache_dir=tmp_path / "cases")
    device, start = next((u.machine, s[0]) for u, s in zip(case.units, case.starts) if u.machine.component is ZIP)
    ss = andes.load(str(path), setup=False, no_output=True, default_config=True)
    ss.add("Fault", {"bus": 4, "tf": 1.0, "tc": 1.1, "xf": 1e-4, "rf": 0.0})
    ss.setup()
    ss.PFlow.config.tol = 1e-12
    assert ss.PFlow.run()
    ss.TDS.init()
    zp, pq = ss.ZIP, ss.PQ
    j, bus = list(pq.idx.v).index(zp.pq.v[0]), list(ss.Bus.idx.v).index(zp.bus.v[0])
    assert device.params == ZIP.params({k: float(getattr(zp, k).v[0]) for k in PERCENTAGES})
    assert start.states == ()
    V0, theta0 = float(ss.Bus.v.v[bus]), float(ss.Bus.a.v[bus])
    assert start.inputs == pytest.approx({"Vs": V0, "theta_vs": theta0, "P0": -float(pq.Ppf.v[j]),
                                          "Q0": -float(pq.Qpf.v[j]), "V0": V0}, rel=1e-10, abs=1e-12)
    ss.TDS.config.update(fixt=1, tstep=0.005, tol=1e-6, no_tqdm=1)
    for t in ANDES_TIMES:
        ss.TDS.config.tf = t
        assert ss.TDS.run() and ss.dae.t == pytest.approx(t)
        ss.TDS.fg_update(ss.exist.tds)
        V, theta = float(ss.Bus.v.v[bus]), float(ss.Bus.a.v[bus])
        assert (V < 0.5) == (t < 1.1)
        u = np.array([V, theta, *(start.inputs[n] for n in ("P0", "Q0", "V0"))])
        I_re, I_im, P, Q = ZIP.output_values(np.zeros(0), u, device.params)
        S = V * np.exp(1j * theta) * complex(I_re, -I_im)
        drawn = float(zp.a.e[0]), float(zp.v.e[0])
        np.testing.assert_allclose([-S.real, -S.imag], drawn, rtol=1e-12, atol=1e-13)
        np.testing.assert_allclose([-P, -Q], drawn, rtol=1e-12, atol=1e-13)
