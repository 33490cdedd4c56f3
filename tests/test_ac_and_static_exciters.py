"""The AC exciters EXAC1, EXAC4, ESAC1A and the static exciters ESST1A, ESST4B
(reference_models.models): their rectifier and inner-loop algebra, their starts, and against ANDES
2.0.0 (where installed) its initialisation of the ieee14 case of each (and EI_33's devices) and its
derivatives and field voltage mid-fault and after clearing."""
from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from reference_models.component import ParameterError
from reference_models.models import STANDARD_MODELS
from reference_models.models.common import network_current
from reference_models.models.esst4b import ESST4BParams, inner_loop
from reference_models.models.exac1 import EXAC1Params, ac_exciter_voltage, ac_field_voltage

MODELS = ("EXAC1", "EXAC4", "ESAC1A", "ESST1A", "ESST4B")
CASES = {name: f"ieee14/ieee14_{name.lower()}.xlsx" for name in MODELS}  # each on GENROU_5 at bus 8
FAULT_BUS = 7  # the only bus next to bus 8


def test_the_exciter_voltage_at_rest_gives_the_field_voltage_through_each_piece_of_the_rectifier_loading():
    for XadIfd, KC in ((1.5, 0.0), (1.5, 0.1), (2.0, 0.56), (3.0, 0.9), (2.5, 3.0)):
        for Efd in (0.05, 0.3, 1.0, 2.5, 6.0):
            VE = ac_exciter_voltage(Efd, XadIfd, KC)
            assert ac_field_voltage(VE, XadIfd, EXAC1Params(KC=KC), math) == pytest.approx(Efd, rel=1e-14, abs=1e-15)
    pieces = {min(3, int(np.searchsorted([0.0, 0.433, 0.75, 1.0], 0.1 * XadIfd / ac_exciter_voltage(E, XadIfd, 0.1))))
              for XadIfd in (1.5, 8.0, 15.0, 30.0) for E in (0.05, 0.5, 2.0)}
    assert pieces == {1, 2, 3}  # every loaded piece of FEX was taken
    with pytest.raises(ValueError, match="no exciter voltage"):
        ac_exciter_voltage(-0.1, 1.5, 0.1)


def test_esst4b_inner_loop_solves_its_field_voltage_feedback_within_and_at_the_limits():
    rng = np.random.default_rng(3)
    for KG, VGMAX in ((1.0, 20.0), (1.0, 2.0), (0.0, 20.0), (0.7, 0.5)):
        p = ESST4BParams(KG=KG, VGMAX=VGMAX, KPM=3.0, VMMIN=-1.0, VMMAX=2.0)
        for LA_y, PI2_xi, VB in zip(rng.uniform(-2, 8, 50), rng.uniform(-1, 1, 50), rng.uniform(0.5, 6, 50)):
            ys, y, VG = inner_loop(LA_y, PI2_xi, VB, p, math)
            assert VG == pytest.approx(min(KG * VB * y, VGMAX), abs=1e-12)
            assert ys == pytest.approx(p.KPM * (LA_y - VG) + PI2_xi, abs=1e-12)
            assert y == pytest.approx(min(max(ys, p.VMMIN), p.VMMAX), abs=1e-12)


def test_esst1a_set_point_carries_andes_constant_uel_where_uelc_is_1():
    component = STANDARD_MODELS["ESST1A"]
    given = {"Vt": 1.02, "Vss": 0.0, "XadIfd": 1.3, "Efd": 1.6}
    _, summed = component.start(given, component.params({"UELc": 1}))
    x, elsewhere = component.start(given, component.params({"UELc": 3}))
    assert summed["Vref"] - elsewhere["Vref"] == pytest.approx(999.0, abs=1e-12)
    assert elsewhere["Vref"] == pytest.approx(1.02 + (1.6 + 0.3) / 80.0, abs=1e-14)
    assert x[3] == pytest.approx(1.6 + 0.3, abs=1e-14)  # VA = Efd + KLR (XadIfd - ILR)
    with pytest.raises(ParameterError, match="parameter UELc "):
        component.params({"UELc": 4})


def test_exac4_field_voltage_is_clipped_to_limits_lowered_by_the_field_current():
    component = STANDARD_MODELS["EXAC4"]
    p = component.params({"KC": 0.5, "VRMAX": 4.0})
    x = np.array([1.0, 0.05, 6.0])  # regulator output above both limits
    assert component.output_values(x, np.array([1.0, 1.05, 2.0]), p)[0] == pytest.approx(3.0)
    assert component.output_values(x, np.array([1.0, 1.05, 1.0]), p)[0] == pytest.approx(3.5)


@pytest.mark.parametrize("name, params", [("EXAC1", {"VRMAX": 1.0}), ("ESAC1A", {"VAMAX": 1.0}),
                                          ("EXAC4", {"VIMAX": 0.01}), ("ESST1A", {"VIMAX": 0.01}),
                                          ("ESST4B", {"VMMAX": 0.2})])
def test_a_start_that_a_limit_would_hold_is_refused_naming_the_model(name, params):
    component = STANDARD_MODELS[name]
    given = {"Vt": 1.0, "theta_vs": 0.1, "I_re": 1.0, "I_im": -0.2, "Vss": 0.0, "XadIfd": 1.5, "Efd": 2.0}
    with pytest.raises(ValueError, match=name):
        component.start(given, component.params(params))


# --- against ANDES 2.0.0 -------------------------------------------------------------------------

def _inputs(ss, name: str, model, i: int) -> dict:
    """Our inputs of ANDES' exciter device i (and its field voltage Efd) at ANDES' current point."""
    machine = ss.GENROU
    j = list(machine.idx.v).index(model.syn.v[i])
    bus = list(ss.Bus.idx.v).index(machine.bus.v[j])
    I_re, I_im = network_current(float(machine.delta.v[j]), float(machine.Id.v[j]), float(machine.Iq.v[j]), math)
    vref = model.vref0 if name == "EXAC4" else model.vref  # ANDES' EXAC4 has only its constant vref0
    values = {"Vt": float(ss.Bus.v.v[bus]), "theta_vs": float(ss.Bus.a.v[bus]), "I_re": I_re, "I_im": I_im,
              "Vref": float(vref.v[i]), "XadIfd": float(model.XadIfd.v[i]), "Efd": float(machine.vf.v[j])}
    values["Vss"] = float(model.Vs.v[i]) if hasattr(model, "Vs") else 0.0
    return values


def _andes_states(model, component, i: int) -> np.ndarray:
    return np.array([float(getattr(model, s).v[i]) for s in component.state_names])


def _andes_rates(ss, model, component, i: int) -> np.ndarray:
    """ANDES' dx/dt (f / Tf) of the device's states; NaN for a state with a zero time constant."""
    rates = []
    for s in component.state_names:
        a = int(getattr(model, s).a[i])
        T = float(ss.dae.Tf[a])
        rates.append(float(ss.dae.f[a]) / T if T != 0 else math.nan)
    return np.array(rates)


def _scaled(difference, values) -> float:
    """The largest |difference| relative to max(1, |values|)."""
    return float(np.max(np.abs(difference) / np.maximum(1.0, np.abs(values))))


def _start_differences(ss, name: str) -> list:
    """[(states, set point, residual)] per device of the model in ss: our start's largest scaled
    differences from ANDES' initial states and vref, and how far ANDES' initial point is from the
    rest it solves for (its states' field voltage, ours at its states and inputs, against the
    machine's: the residual its initialisation's iterations left)."""
    from andes_reference import params

    component, model = STANDARD_MODELS[name], getattr(ss, name)
    rows = []
    for i in range(model.n):
        given, p = _inputs(ss, name, model, i), params(model, component, i)
        x0, inputs = component.start(given, p)
        theirs = _andes_states(model, component, i)
        u = np.array([given[n] for n in component.input_names])
        rows.append((_scaled(x0 - theirs, theirs), _scaled(inputs["Vref"] - given["Vref"], given["Vref"]),
                     _scaled(component.output_values(theirs, u, p)[0] - given["Efd"], given["Efd"])))
    return rows


@pytest.mark.andes
@pytest.mark.parametrize("name", MODELS)
def test_start_gives_andes_initial_states_and_set_point(name):
    """ieee14 with the model on GENROU_5: from ANDES' load flow, field voltage and machine signals,
    our start gives ANDES' initial states and vref to rounding (relative to max(1, |value|))."""
    pytest.importorskip("andes")
    (states, set_point, _), = _andes_run(name)["start"]
    assert states < 1e-10 and set_point < 1e-12, (states, set_point)


@pytest.mark.andes
def test_start_gives_andes_initial_states_of_the_ei33_ac_and_static_exciters_to_its_own_residual():
    """EI_33's three EXAC1 (saturation, KD), its EXAC4 and its ESST4B (integral gain KIR, KG = 0):
    our start gives ANDES' initial states to rounding, but for the EXAC1 whose rest lies next to a
    breakpoint of FEX (IN = 0.423), where ANDES' iterations stop 7.6e-8 from its field voltage (its
    initialisation of EI_33 fails on an IEEEG1): there ours differ by what that residual makes."""
    pytest.importorskip("andes")
    from andes_reference import load

    ss = load("ei/EI_33.xlsx")
    residuals = []
    for name, count in (("EXAC1", 3), ("EXAC4", 1), ("ESST4B", 1)):
        assert getattr(ss, name).n == count
        for states, set_point, residual in _start_differences(ss, name):
            assert states < 1e-10 + 10.0 * residual and set_point < 1e-12 + residual, (name, states, residual)
            residuals.append(residual)
    assert sum(r > 1e-10 for r in residuals) == 1 and max(residuals) < 1e-7


@functools.cache
def _andes_run(name: str) -> dict:
    """ANDES on the model's ieee14 case with a fault at bus 7 1.0-1.1 s (tol 1e-6, fixed 5 ms steps):
    {"start": _start_differences after its initialisation, "transient": [(t, rate difference,
    ANDES' largest |dx/dt|, our largest held rate, output difference)] at 1.05 s (mid-fault) and
    2.5 s}: our dx/dt at ANDES' states and inputs against ANDES' f / Tf (states ANDES treats as
    algebraic are held in ours: rate 0), and our Efd against ANDES' vout, both relative to
    max(1, |ANDES' value|)."""
    import andes

    from andes_reference import params
    from reference_models.grid.andes_case import configure_andes_logging

    configure_andes_logging(andes, 40)
    ss = andes.load(andes.get_case(CASES[name]), setup=False, no_output=True, default_config=True)
    ss.add("Fault", {"bus": FAULT_BUS, "tf": 1.0, "tc": 1.1, "xf": 1e-4, "rf": 0.0})
    ss.setup()
    ss.PFlow.run()
    ss.TDS.config.update(tol=1e-6, fixt=1, tstep=0.005, no_tqdm=1)
    ss.TDS.init()
    run = {"start": _start_differences(ss, name), "transient": []}
    component, model = STANDARD_MODELS[name], getattr(ss, name)
    p = params(model, component, 0)
    for t in (1.05, 2.5):
        ss.TDS.config.tf = t
        ss.TDS.run()
        ss.TDS.fg_update(ss.exist.tds)
        given = _inputs(ss, name, model, 0)
        u = np.array([given[n] for n in component.input_names])
        x = _andes_states(model, component, 0)
        theirs = _andes_rates(ss, model, component, 0)
        ours = component.rhs(x, u, p)
        held = np.isnan(theirs)
        vout = float(model.vout.v[0])
        run["transient"].append((float(ss.dae.t), _scaled((ours - theirs)[~held], theirs[~held]),
                                 float(np.abs(theirs[~held]).max()), float(np.abs(ours[held]).max(initial=0.0)),
                                 _scaled(component.output_values(x, u, p)[0] - vout, vout)))
    return run


@pytest.mark.andes
@pytest.mark.parametrize("name", MODELS)
def test_derivatives_and_field_voltage_match_andes_mid_fault_and_after_clearing(name):
    """Mid-fault (1.05 s, the terminal voltage collapsed) and after clearing (2.5 s): at ANDES' states
    and inputs our dx/dt is ANDES' f / Tf and our Efd ANDES' vout, to what ANDES' Newton tolerance
    (1e-6) leaves in its algebraic variables."""
    pytest.importorskip("andes")
    for t, rate, andes_rate, held, output in _andes_run(name)["transient"]:
        assert andes_rate > 1e-3, (t, andes_rate)  # not at rest
        assert rate < 1e-6 and output < 1e-8 and held == 0.0, (t, rate, output, held)
