"""Our standard models against ANDES' initialisation of its shipped cases (needs `andes`).

For each device of a model in a case: ANDES runs its power flow and time-domain initialisation;
our machines start from the same bus voltage and power injection (`operating_point`), our
controllers from the same field voltage, mechanical power or input signal (`initialise` /
`equilibrium`). `compare(case)` gives per model the largest differences of the initial states, of
the set points and of our derivatives there (0 at rest), and ANDES' own derivative at the point.
"""
from __future__ import annotations

import math

import numpy as np

from reference_models.models import STANDARD_MODELS, esst3a, exdc2, exst1, gencls, genrou, ieeeg1, ieeex1
from reference_models.models import sexs, tgov1, tgov1n
from reference_models.models.common import network_current

MACHINES = {"GENROU": genrou, "GENCLS": gencls}
EXCITERS = {"SEXS": sexs, "EXST1": exst1, "EXDC2": exdc2, "IEEEX1": ieeex1, "ESST3A": esst3a}
GOVERNORS = {"TGOV1": tgov1, "TGOV1N": tgov1n, "IEEEG1": ieeeg1}
# our state name -> ANDES variable name where they differ
ANDES_NAMES = {"ESST3A": {"VR": "LAW1_y", "VM": "LAW2_y"}}


def load(case: str):
    """The ANDES system of a shipped case after power flow and TDS initialisation."""
    import andes

    andes.config_logger(stream_level=40)
    ss = andes.load(andes.get_case(case), setup=True, no_output=True, default_config=True)
    ss.PFlow.run()
    ss.TDS.init()
    return ss


def params(model, component, i: int, extra: dict | None = None):
    """Our parameters of device i from ANDES' input data (before its base conversion)."""
    values = {}
    for name in component.params_type.__dataclass_fields__:
        if hasattr(model, name) and hasattr(getattr(model, name), "vin"):
            values[name] = float(getattr(model, name).vin[i])
    values.update(extra or {})
    return component.params(values)


def _v(var, i):
    return float(var.v[i])


def _machine(ss, syn_idx):
    """(model, position) of a SynGen device."""
    for name in MACHINES:
        model = getattr(ss, name)
        if syn_idx in list(model.idx.v):
            return model, list(model.idx.v).index(syn_idx)
    raise KeyError(syn_idx)


def _machine_signals(ss, syn_idx) -> dict:
    """The machine's signals as our models take them (machine base where they are powers)."""
    model, j = _machine(ss, syn_idx)
    bus = list(ss.Bus.idx.v).index(model.bus.v[j])
    k = ss.config.mva / float(model.Sn.v[j])  # system -> machine base for powers
    delta = _v(model.delta, j)
    I_re, I_im = network_current(delta, _v(model.Id, j), _v(model.Iq, j), math)
    return dict(Vt=float(ss.Bus.v.v[bus]), theta=float(ss.Bus.a.v[bus]), omega=_v(model.omega, j),
                Pe=_v(model.te, j) * k, Pm=_v(model.tm, j) * k, Efd=_v(model.vf, j),
                XadIfd=_v(model.XadIfd, j) if hasattr(model, "XadIfd") else 0.0, I_re=I_re, I_im=I_im)


def _andes_states(model, component, i, name):
    names = ANDES_NAMES.get(name, {})
    return np.array([_v(getattr(model, names.get(s, s)), i) for s in component.state_names])


def _andes_rates(ss, model, component, i, name):
    """ANDES' dx/dt of the device's states at the current point (f / Tf)."""
    names = ANDES_NAMES.get(name, {})
    rates = []
    for s in component.state_names:
        var = getattr(model, names.get(s, s))
        a = int(var.a[i])
        T = float(ss.dae.Tf[a])
        rates.append(float(ss.dae.f[a]) / T if T != 0 else float("nan"))
    return np.array(rates)


def compare(case: str) -> dict:
    """{model: {"devices", "state", "set_point", "our_rate", "andes_rate"}}: the largest absolute
    differences of our initial states and set points from ANDES', our largest |dx/dt| at ANDES'
    initial point, and ANDES' own largest |dx/dt| there."""
    ss = load(case)
    results = {}

    def record(name, state_diff, set_diff, our_rate, andes_rate):
        r = results.setdefault(name, dict(devices=0, state=0.0, set_point=0.0, our_rate=0.0, andes_rate=0.0))
        r["devices"] += 1
        for key, value in (("state", state_diff), ("set_point", set_diff), ("our_rate", our_rate),
                           ("andes_rate", andes_rate)):
            r[key] = max(r[key], float(value))

    for name, module in MACHINES.items():
        model, component = getattr(ss, name), STANDARD_MODELS[name]
        for i in range(model.n):
            p = params(model, component, i, {"Sb": ss.config.mva, "Sn": float(model.Sn.v[i]),
                                             "fn": float(model.fn.v[i])})
            bus = list(ss.Bus.idx.v).index(model.bus.v[i])
            V, a = float(ss.Bus.v.v[bus]), float(ss.Bus.a.v[bus])
            x, Pm, Efd = module.operating_point(V, a, float(model.p0.v[i]), float(model.q0.v[i]), p)
            ours = _andes_states(model, component, i, name)
            signals = _machine_signals(ss, model.idx.v[i])
            u = np.array([V, a, signals["Pm"], signals["Efd"]])
            record(name, np.abs(x - ours).max(), max(abs(Pm - signals["Pm"]), abs(Efd - signals["Efd"])),
                   np.abs(component.rhs(ours, u, p)).max(), np.abs(_andes_rates(ss, model, component, i, name)).max())

    for name, module in EXCITERS.items():
        model, component = getattr(ss, name), STANDARD_MODELS[name]
        for i in range(model.n):
            s = _machine_signals(ss, model.syn.v[i])
            Vss = 0.0
            base = {"SEXS": [s["Vt"], 0.0, Vss], "EXST1": [s["Vt"], 0.0, Vss, s["XadIfd"]],
                    "EXDC2": [s["Vt"], 0.0, Vss, s["omega"]], "IEEEX1": [s["Vt"], 0.0, Vss],
                    "ESST3A": [s["Vt"], s["theta"], s["I_re"], s["I_im"], 0.0, Vss, s["XadIfd"]]}[name]
            p = params(model, component, i)
            x, Vref = module.initialise(s["Efd"], base, p)
            ref_at = 4 if name == "ESST3A" else 1
            base[ref_at] = Vref
            ours = _andes_states(model, component, i, name)
            record(name, np.abs(x - ours).max(), abs(Vref - _v(model.vref, i)),
                   np.abs(component.rhs(ours, np.array(base), p)).max(),
                   np.abs(_andes_rates(ss, model, component, i, name)).max())

    for name, module in GOVERNORS.items():
        model, component = getattr(ss, name), STANDARD_MODELS[name]
        for i in range(model.n):
            if name == "IEEEG1" and model.syn2.v[i] is not None:
                continue  # a turbine on two machines: not modelled
            s = _machine_signals(ss, model.syn.v[i])
            p = params(model, component, i)
            x, Pref = module.initialise(s["Pm"], [s["omega"], 0.0], p)
            # ANDES' governor powers are on the system base: ours on the machine base
            k = ss.config.mva / float(model.Sn.v[i])
            scale = np.array([1.0 if state == "LL_x" and name == "IEEEG1" else k for state in component.state_names])
            ours = _andes_states(model, component, i, name) * scale
            if name == "TGOV1":  # pref = R tm0, both converted by ANDES: the product is base-free
                andes_ref = _v(model.pref, i)
            else:
                andes_ref = (_v(model.pref, i) if name == "TGOV1N" else float(model.tm012.v[i])) * k
            record(name, np.abs(x - ours).max(), abs(Pref - andes_ref),
                   np.abs(component.rhs(ours, np.array([s["omega"], Pref]), p)).max(),
                   np.abs(_andes_rates(ss, model, component, i, name)).max())

    model, component = ss.IEEEST, STANDARD_MODELS["IEEEST"]
    for i in range(model.n):
        exciter = next(getattr(ss, n) for n in EXCITERS if model.avr.v[i] in list(getattr(ss, n).idx.v))
        syn = exciter.syn.v[list(exciter.idx.v).index(model.avr.v[i])]
        s = _machine_signals(ss, syn)
        p = params(model, component, i)
        u = np.array([s["omega"], s["Pe"], s["Vt"]])
        x = component.steady_state(u, p)
        ours = _andes_states(model, component, i, "IEEEST")
        record("IEEEST", np.abs(x - ours).max(), 0.0, np.abs(component.rhs(ours, u, p)).max(),
               np.abs(_andes_rates(ss, model, component, i, "IEEEST")).max())
    return results
