"""Model Exchange of the native reference FMUs (FMI 2.0 and 3.0, beside co-simulation in one FMU):
fmpy reads and validates both interfaces; fmpy's own CVode integration of an exciter driven onto
and off its non-windup limits equals the FMU's co-simulation on the same inputs; a machine with
held inputs stays at rest; the event update places a state pushed beyond a limit on it and says so;
the locked branches travel with the FMU state; misuse is an error with a logged reason, never a
crash; the surrogate FMU stays co-simulation only."""
import ctypes

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Model, FMU2Slave
from fmpy.fmi3 import FMU3Model, FMU3Slave
from fmpy.validation import validate_fmu

from cosim import fmi2_logging
from fmu_export.build_cache import cached_native_reference_fmu
from fmu_export.c_equations import parameter_space, switching_c_source
from fmu_export.python_reference_fmu import machine_params
from reference_models.components import component

SEXS = component("sexs")
EXCITER = {"EMIN": 0.0, "EMAX": 3.0}  # limits the voltage steps below drive the output onto, both
# Vt [pu] over the run (time [s], value), steps at 1 s (a dip: the output rises to its ceiling) and
# 3 s (a rise: it falls to its floor); Vref = 1.1, Vss = 0 held at their start values
VT_STEPS = [(0.0, 1.0), (1.0, 1.0), (1.0, 0.8), (3.0, 0.8), (3.0, 1.2), (6.0, 1.2)]
RTOL = 1e-10  # CVode's relative tolerance (its absolute one: this times the states' nominal, 1)


@pytest.fixture(scope="module", params=[2, 3], ids=["fmi2", "fmi3"])
def exciter(request, fmu_cache):
    """(path, FMI version) of SEXS' native reference FMU with EXCITER's limits."""
    path = cached_native_reference_fmu("SEXSReference", component=SEXS, params=EXCITER, fmi_version=request.param,
                                       cache=fmu_cache)
    return path, request.param


def n_switching(comp, params=None) -> int:
    return switching_c_source(comp, parameter_space(comp, machine_params(comp, params)))[0]


def test_fmpy_validates_the_fmu_and_reads_both_interfaces(exciter):
    path, version = exciter
    assert validate_fmu(str(path)) == []
    md = read_model_description(str(path), validate=True)
    assert md.coSimulation is not None and md.modelExchange is not None
    assert md.modelExchange.modelIdentifier == md.coSimulation.modelIdentifier
    assert md.numberOfContinuousStates == SEXS.n_states
    assert md.numberOfEventIndicators == n_switching(SEXS, EXCITER) > 0
    # each state's derivative names it, in the states' order
    assert [d.variable.name for d in md.derivatives] == [f"der({n})" for n in SEXS.state_names]
    assert [d.variable.derivative.name for d in md.derivatives] == list(SEXS.state_names)


def run(path, fmi_type, states):
    signal = np.array(VT_STEPS, dtype=[("time", float), ("Vt", float)])
    return simulate_fmu(str(path), fmi_type=fmi_type, solver="CVode", relative_tolerance=RTOL, stop_time=6.0,
                        output_interval=0.01, input=signal, output=list(states))


def test_model_exchange_under_cvode_equals_cosimulation_through_the_limits(exciter):
    path, _ = exciter
    cs, me = run(path, "CoSimulation", SEXS.state_names), run(path, "ModelExchange", SEXS.state_names)
    # ME also records the event instants (where the inputs step and the limits are reached) and, at an
    # event, the values before and after it: compare at the communication points, the first value at
    # each (before the event there, as co-simulation's step ends before the next one starts)
    times = np.round(cs["time"], 9)
    at = [np.flatnonzero(np.isclose(me["time"], t, rtol=0, atol=1e-9))[0] for t in times]
    for name in SEXS.state_names:
        scale = max(1.0, float(np.max(np.abs(cs[name]))))
        assert np.max(np.abs(me[name][at] - cs[name])) <= 1e-6 * scale, name
    # the output reached its ceiling and its floor, and rested on each
    assert np.isclose(np.max(me["LAW_y"]), EXCITER["EMAX"], atol=1e-9)
    assert np.isclose(np.min(me["LAW_y"]), EXCITER["EMIN"], atol=1e-9)
    assert len(me) > len(cs)  # the events between communication points


def test_ieeet3_under_cvode_equals_cosimulation_through_its_voltage_steps(fmu_cache):
    """IEEET3 through the run of tests/test_standard_model_fmus.py: Vt = 0.2 pu from 0.1 s puts
    SQE = |KP V + j KI I|^2 - (0.78 XadIfd)^2 below 0, Vt back at 0.6 s (Vref 3.0) above. fmpy's
    CVode sets the inputs of before the step again at 0.6 s (its root function takes the left
    value there) after the event locked SQE > 0: the locked branch's root stays finite past SQE = 0
    (blocks.sqrt_positive_part; it took sqrt of a negative number, NaN, and CVode stopped)."""
    import sys
    sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1] / "benchmarks"))
    from model_exchange import compare

    row = compare("IEEET3", 2, fmu_cache)
    assert row["status"] == "agrees" and row["difference"] <= 1e-6, row


@pytest.mark.parametrize("name", ["REGCA1", "REGCP1"])
def test_a_converter_held_on_its_falling_lvpl_limit_agrees_under_both_interfaces(fmu_cache, name):
    """The run of tests/test_standard_model_fmus.py: Vs = 0.45 pu from 0.1 s drags the filtered
    voltage and with it LVPL below the active current, which slides down on the limit. Held at rate
    0 and placed on the limit after each step (ANDES' way), Model Exchange and co-simulation differed
    by 1.0e-2 pu, the limit's fall between an integrator step and a communication point; moving
    with the limit, they agree."""
    import sys
    sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1] / "benchmarks"))
    from model_exchange import compare

    row = compare(name, 2, fmu_cache)
    assert row["status"] == "agrees" and row["difference"] <= 1e-6, row


def test_a_non_finite_rate_is_discarded_with_a_logged_reason(exciter, unzipped):
    """A state far enough out that its rate overflows: fmi2GetDerivatives (fmi3's too) returns
    Discard (the FMI's answer for a right-hand side outside its domain: try a smaller step) with the
    reason logged, and the instance goes on."""
    path, version = exciter
    me = Exchange(path, version, unzipped)
    me.initialise()
    me.update()
    me.fmu.enterContinuousTimeMode()
    me.set_states([0.3, -1.7e308])  # (K LL_y - LAW_y) / TE overflows
    get = "fmi2GetDerivatives" if version == 2 else "fmi3GetContinuousStateDerivatives"
    with pytest.raises(FMICallException) as raised:
        me.derivatives()
    assert raised.value.status == 2  # Discard
    assert any(f"{get}: the derivative of state 1 is inf" in m for m in me.messages), me.messages
    me.set_states([0.3, 3.0])
    assert np.all(np.isfinite(me.derivatives()))
    me.free()


def test_a_machine_with_held_inputs_stays_at_rest_under_model_exchange(fmu_cache):
    genrou = component("genrou")
    path = cached_native_reference_fmu("GENROUReference", component=genrou, cache=fmu_cache)
    md = read_model_description(str(path))
    start = {v.name[:-1]: float(v.start) for v in md.modelVariables if v.name[:-1] in genrou.state_names
             and v.causality == "parameter"}
    result = simulate_fmu(str(path), fmi_type="ModelExchange", solver="CVode", relative_tolerance=RTOL,
                          stop_time=5.0, output_interval=0.5, output=list(genrou.state_names))
    for name in genrou.state_names:
        assert np.max(np.abs(result[name] - start[name])) <= 1e-9 * max(1.0, abs(start[name])), name


class Exchange:
    """One Model Exchange instance of an FMU through fmpy (FMI 2.0 or 3.0), what it logs in `messages`."""

    def __init__(self, path, version, unzipped):
        md = read_model_description(str(path))
        self.version, self.messages, self.md = version, [], md
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        kind = FMU2Model if version == 2 else FMU3Model
        self.fmu = kind(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.modelExchange.modelIdentifier,
                        instanceName="me")
        if version == 2:
            self._callbacks, self._key = fmi2_logging.callbacks(self._log)
            self.fmu.instantiate(callbacks=self._callbacks, loggingOn=False)
        else:
            self.fmu.instantiate(loggingOn=False, logMessage=self._log3)
        self.n_x, self.n_g = md.numberOfContinuousStates, md.numberOfEventIndicators

    def _log(self, status, category, message):
        self.messages.append(message.decode() if message else "")

    def _log3(self, environment, status, category, message):
        self.messages.append(message.decode() if message else "")

    def initialise(self, **start):
        if self.version == 2:
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()
        else:
            self.fmu.enterInitializationMode(startTime=0.0)
        self.set(**start)
        self.fmu.exitInitializationMode()

    def set(self, **values):
        refs, numbers = [self.vr[n] for n in values], list(values.values())
        (self.fmu.setReal if self.version == 2 else self.fmu.setFloat64)(refs, numbers)

    def update(self) -> bool:
        """the event update; whether it moved a state"""
        flags = self.fmu.newDiscreteStates() if self.version == 2 else self.fmu.updateDiscreteStates()
        assert not flags[0] and not flags[1] and not flags[4]  # no iteration, no termination, no time event
        return bool(flags[3])

    def array(self, call, n) -> np.ndarray:
        values = (ctypes.c_double * max(n, 1))()
        call(values, n)
        return np.array(values[:n])

    def states(self):
        return self.array(self.fmu.getContinuousStates, self.n_x)

    def derivatives(self):
        get = self.fmu.getDerivatives if self.version == 2 else self.fmu.getContinuousStateDerivatives
        return self.array(get, self.n_x)

    def indicators(self):
        return self.array(self.fmu.getEventIndicators, self.n_g)

    def set_states(self, x):
        self.fmu.setContinuousStates((ctypes.c_double * len(x))(*x), len(x))

    def refused(self, call, reason):
        """call fails with an FMI error and the FMU logged `reason`"""
        with pytest.raises(FMICallException):
            call()
        assert any(reason in m for m in self.messages), self.messages

    def free(self):
        self.fmu.freeInstance()
        if self.version == 2:
            fmi2_logging.release(self._key)


@pytest.fixture(scope="module")
def unzipped(exciter, tmp_path_factory):
    return extract(str(exciter[0]), unzipdir=str(tmp_path_factory.mktemp("me")))


def test_misuse_is_an_error_with_a_logged_reason_and_the_instance_stays_usable(exciter, unzipped):
    path, version = exciter
    me = Exchange(path, version, unzipped)
    get = "fmi2GetDerivatives" if version == 2 else "fmi3GetContinuousStateDerivatives"
    me.refused(me.derivatives, f"{get} is not allowed in the current state")  # before initialisation
    me.refused(lambda: me.fmu.enterContinuousTimeMode(), "is not allowed in the current state")
    me.initialise()
    me.refused(lambda: me.set_states([1.0, 2.0]), "is not allowed in the current state")  # in event mode
    me.update()
    me.fmu.enterContinuousTimeMode()
    me.refused(lambda: me.array(me.fmu.getContinuousStates, me.n_x + 1), "values for the FMU's 2 continuous states")
    me.refused(lambda: me.array(me.fmu.getEventIndicators, me.n_g - 1), f"values for the FMU's {me.n_g} event")
    me.refused(lambda: me.set_states([1.0]), "1 values for the FMU's 2 continuous states")
    me.refused(lambda: me.set_states([1.0, float("nan")]), "state 1: nan is not a finite number")
    me.refused(lambda: me.fmu.setTime(float("inf")), "is not a finite number")
    me.refused(lambda: me.update(), "is not allowed in the current state")  # not in event mode
    me.refused(lambda: me.set(K=30.0), "fixed after initialization")
    step = ((ctypes.c_double(0.0), ctypes.c_double(0.01), ctypes.c_int(1)) if version == 2 else
            (ctypes.c_double(0.0), ctypes.c_double(0.01), ctypes.c_bool(True),
             *[ctypes.byref(ctypes.c_bool()) for _ in range(3)], ctypes.byref(ctypes.c_double())))
    assert getattr(me.fmu.dll, f"fmi{version}DoStep")(ctypes.c_void_p(me.fmu.component), *step) == 3  # Error
    assert any(f"fmi{version}DoStep is not allowed in the current state" in m for m in me.messages)
    # still usable: at rest, every rate is zero and the states are where they started
    assert np.max(np.abs(me.derivatives())) < 1e-12
    assert me.states() == pytest.approx([float(v.start) for v in me.md.modelVariables if v.name in ("LL_x0", "LAW_y0")])
    me.free()


def test_a_cosimulation_instance_refuses_the_model_exchange_calls(exciter, unzipped):
    path, version = exciter
    md = read_model_description(str(path))
    messages = []
    slave = (FMU2Slave if version == 2 else FMU3Slave)(guid=md.guid, unzipDirectory=unzipped, instanceName="cs",
                                                       modelIdentifier=md.coSimulation.modelIdentifier)
    if version == 2:
        callbacks, key = fmi2_logging.callbacks(lambda status, category, message: messages.append(message.decode()))
        slave.instantiate(callbacks=callbacks)
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
    else:
        slave.instantiate(logMessage=lambda env, status, category, message: messages.append(message.decode()))
        slave.enterInitializationMode(startTime=0.0)
    slave.exitInitializationMode()
    x, component = (ctypes.c_double * 2)(), ctypes.c_void_p(slave.component)
    derivatives = "fmi2GetDerivatives" if version == 2 else "fmi3GetContinuousStateDerivatives"
    assert getattr(slave.dll, derivatives)(component, x, ctypes.c_size_t(2)) == 3  # Error
    assert getattr(slave.dll, f"fmi{version}EnterEventMode")(component) != 0
    assert any(f"{derivatives}: the instance was instantiated for co-simulation, not Model Exchange" in m
               for m in messages), messages
    slave.doStep(0.0, 0.01)  # still a working co-simulation instance
    slave.freeInstance()
    if version == 2:
        fmi2_logging.release(key)


def test_the_event_update_places_a_state_pushed_beyond_its_limit_on_it_and_says_so(exciter, unzipped):
    path, version = exciter
    me = Exchange(path, version, unzipped)
    me.initialise()
    assert not me.update()  # at rest within the limits: nothing moves
    me.fmu.enterContinuousTimeMode()
    # the output beyond its ceiling, the lead-lag's output pushing it further out: K LL_y = 20 (0.4 (0.1 - 0.3)
    # + 0.3) = 4.4 pu (SEXS' default TATB = 0.4, K = 20, TE = 0.1 s; vi = Vref - Vt = 0.1 pu)
    me.set_states([0.3, 3.5])
    # the branches locked at the start: the rate is the unlimited lag's, and the step's end asks for an event
    assert me.derivatives()[1] == pytest.approx((4.4 - 3.5) / 0.1)
    assert me.fmu.completedIntegratorStep()[0]
    me.fmu.enterEventMode()
    assert me.update()
    assert list(me.states()) == [0.3, EXCITER["EMAX"]]  # placed exactly on the limit
    assert me.derivatives()[1] == 0.0  # and held there
    me.set(Vt=1.5)  # an input set in event mode: the lag is pulled back inward, the next update relocks
    assert not me.update()
    assert me.derivatives()[1] < 0.0
    me.free()


def test_the_locked_branches_travel_with_the_fmu_state_and_a_corrupt_one_is_refused(exciter, unzipped):
    path, version = exciter
    me = Exchange(path, version, unzipped)
    me.initialise()
    me.update()
    me.fmu.enterContinuousTimeMode()
    me.set_states([0.2, 3.0])
    me.fmu.enterEventMode()
    me.update()  # on the ceiling: the held branch locked
    me.fmu.enterContinuousTimeMode()
    state = me.fmu.getFMUState() if version == 3 else me.fmu.getFMUstate()
    serialize = me.fmu.serializeFMUState if version == 3 else me.fmu.serializeFMUstate
    deserialize = me.fmu.deserializeFMUState if version == 3 else me.fmu.deSerializeFMUstate
    restore = me.fmu.setFMUState if version == 3 else me.fmu.setFMUstate
    data = bytearray(serialize(state))
    me.set_states([0.0, 2.0])  # elsewhere, then back through the bytes
    restore(deserialize(bytes(data)))
    assert list(me.states()) == [0.2, 3.0] and me.derivatives()[1] == 0.0
    # the state ends with the int lock_due (whether the next event is a full lock) and 4 bytes of padding:
    # a value that is not 0 or 1 is refused
    data[-8:-4] = (7).to_bytes(4, "little")
    me.refused(lambda: deserialize(bytes(data)), "lock_due is 7, not 0 or 1")
    me.free()


def test_the_surrogate_fmu_stays_cosimulation_only(fmu_path):
    md = read_model_description(str(fmu_path))
    assert md.modelExchange is None and md.numberOfEventIndicators == 0
