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

from reference_models.grid.andes_case import configure_andes_logging
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

    configure_andes_logging(andes, 40)
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


def _pss_output(ss, exciter_idx) -> float:
    """The stabiliser signal ANDES feeds the exciter (0 without a stabiliser)."""
    model = ss.IEEEST
    for i in range(model.n):
        if model.avr.v[i] == exciter_idx:
            return float(model.vsout.v[i])
    return 0.0


def devices(ss):
    """Per device of our models in the system: (name, module, params, u, x_andes, andes model, i,
    state scale), with the inputs u and ANDES' states x_andes as our model takes them (machine
    base for governors' powers)."""
    for name, module in MACHINES.items():
        model, component = getattr(ss, name), STANDARD_MODELS[name]
        for i in range(model.n):
            p = params(model, component, i, {"Sb": ss.config.mva, "Sn": float(model.Sn.v[i]),
                                             "fn": float(model.fn.v[i])})
            s = _machine_signals(ss, model.idx.v[i])
            u = np.array([s["Vt"], s["theta"], s["Pm"], s["Efd"]])
            yield name, module, p, u, _andes_states(model, component, i, name), model, i, None

    for name, module in EXCITERS.items():
        model, component = getattr(ss, name), STANDARD_MODELS[name]
        for i in range(model.n):
            s = _machine_signals(ss, model.syn.v[i])
            Vref, Vss = _v(model.vref, i), _pss_output(ss, model.idx.v[i])
            u = {"SEXS": [s["Vt"], Vref, Vss], "EXST1": [s["Vt"], Vref, Vss, s["XadIfd"]],
                 "EXDC2": [s["Vt"], Vref, Vss, s["omega"]], "IEEEX1": [s["Vt"], Vref, Vss],
                 "ESST3A": [s["Vt"], s["theta"], s["I_re"], s["I_im"], Vref, Vss, s["XadIfd"]]}[name]
            yield (name, module, params(model, component, i), np.array(u),
                   _andes_states(model, component, i, name), model, i, None)

    for name, module in GOVERNORS.items():
        model, component = getattr(ss, name), STANDARD_MODELS[name]
        for i in range(model.n):
            if name == "IEEEG1" and model.syn2.v[i] is not None:
                continue  # a turbine on two machines: not modelled
            s = _machine_signals(ss, model.syn.v[i])
            # ANDES' governor powers are on the system base: ours on the machine base
            k = ss.config.mva / float(model.Sn.v[i])
            scale = np.array([1.0 if state == "LL_x" and name == "IEEEG1" else k for state in component.state_names])
            if name == "TGOV1":  # pref = R tm0, both converted by ANDES: the product is base-free
                Pref = _v(model.pref, i)
            else:
                Pref = (_v(model.pref, i) if name == "TGOV1N" else float(model.tm012.v[i])) * k
            extra = {"Sn": float(model.Sn.v[i]), "Sb": ss.config.mva} if name == "IEEEG1" else None
            yield (name, module, params(model, component, i, extra), np.array([s["omega"], Pref]),
                   _andes_states(model, component, i, name) * scale, model, i, scale)

    model, component = ss.IEEEST, STANDARD_MODELS["IEEEST"]
    for i in range(model.n):
        exciter = next(getattr(ss, n) for n in EXCITERS if model.avr.v[i] in list(getattr(ss, n).idx.v))
        s = _machine_signals(ss, exciter.syn.v[list(exciter.idx.v).index(model.avr.v[i])])
        yield ("IEEEST", None, params(model, component, i), np.array([s["omega"], s["Pe"], s["Vt"]]),
               _andes_states(model, component, i, "IEEEST"), model, i, None)


def _record(results, name, **values):
    r = results.setdefault(name, dict(devices=0, **{key: 0.0 for key in values}))
    r["devices"] += 1
    for key, value in values.items():
        r[key] = max(r[key], float(value))


def compare(case: str) -> dict:
    """{model: {"devices", "state", "set_point", "our_rate", "andes_rate"}}: the largest absolute
    differences of our initial states and set points (Pm and Efd of a machine, Vref of an exciter,
    Pref of a governor) from ANDES', our largest |dx/dt| at ANDES' initial point, and ANDES' own
    largest |dx/dt| there."""
    ss = load(case)
    results = {}
    for name, module, p, u, x_andes, model, i, _ in devices(ss):
        component = STANDARD_MODELS[name]
        if name in MACHINES:
            bus = list(ss.Bus.idx.v).index(model.bus.v[i])
            x, Pm, Efd = module.operating_point(u[0], u[1], float(model.p0.v[i]), float(model.q0.v[i]), p)
            set_diff = max(abs(Pm - u[2]), abs(Efd - u[3]))
        elif name in EXCITERS:
            ref_at = 4 if name == "ESST3A" else 1
            x, Vref = module.initialise(_v(_machine(ss, model.syn.v[i])[0].vf, _machine(ss, model.syn.v[i])[1]), u, p)
            set_diff = abs(Vref - u[ref_at])
        elif name in GOVERNORS:
            # the governor's own start, given its speed and the mechanical power its machine demands
            solved = component.initialisation.solves
            given = {n: float(v) for n, v in zip(component.input_names, u) if n not in solved}
            power = component.ports.output("mechanical_power")
            x, found = component.start({**given, power: _machine_signals(ss, model.syn.v[i])["Pm"]}, p)
            set_diff = max(abs(found[n] - u[component.input_names.index(n)]) for n in solved)
        else:
            x, set_diff = component.steady_state(u, p), 0.0
        _record(results, name, state=np.abs(x - x_andes).max(), set_point=set_diff,
                our_rate=np.abs(component.rhs(x_andes, u, p)).max(),
                andes_rate=np.abs(_andes_rates(ss, model, component, i, name)).max())
    return results


def run_to(ss, times, tol: float = 1e-6, tstep: float = 0.005):
    """Yield each of `times` [s] once ANDES' fixed-step time-domain simulation of `ss` (Newton
    tolerance tol, step tstep [s]) has reached it, with its f evaluated at the point reached
    (fg_update); AssertionError where its TDS stops short."""
    ss.TDS.config.update(tol=tol, fixt=1, tstep=tstep, no_tqdm=1)
    for t in times:
        ss.TDS.config.tf = t
        ss.TDS.run()
        ss.TDS.fg_update(ss.exist.tds)
        reached = float(ss.dae.t)
        assert math.isclose(reached, t, rel_tol=1e-6, abs_tol=1e-12), f"ANDES' TDS stopped at {reached} s, not {t} s"
        yield t


def compare_in_transient(case: str, t: float, fault_bus=None, tol: float = 1e-6) -> dict:
    """{model: {"devices", "rate", "andes_rate", "held_rate", "output", "at_limit"}}: ANDES runs the case (its own events,
    and a three-phase fault at `fault_bus` from 1.0 s to 1.1 s where given) to time t [s], its f
    is evaluated at the point it reached, and our derivatives at ANDES' states and inputs there
    are compared with ANDES' dx/dt (f / Tf): the largest absolute difference, ANDES' largest
    |dx/dt|, our largest |dx/dt| of the states ANDES treats as algebraic (a zero time constant:
    ours are held, 0), the largest difference of the main output (`output`), and how many of the model's devices have a non-windup state at a limit there."""
    import andes

    configure_andes_logging(andes, 40)
    ss = andes.load(andes.get_case(case), setup=False, no_output=True, default_config=True)
    if fault_bus is not None:
        ss.add("Fault", {"bus": fault_bus, "tf": 1.0, "tc": 1.1, "xf": 1e-4, "rf": 0.0})
    ss.setup()
    ss.PFlow.run()
    ss.TDS.config.tf = t
    ss.TDS.config.tol = tol
    ss.TDS.config.fixt = 1
    ss.TDS.config.tstep = 0.005
    ss.TDS.config.no_tqdm = 1
    ss.TDS.run()
    ss.TDS.fg_update(ss.exist.tds)
    results = {}
    for name, _, p, u, x_andes, model, i, scale in devices(ss):
        component = STANDARD_MODELS[name]
        theirs = _andes_rates(ss, model, component, i, name) * (1.0 if scale is None else scale)
        ours = component.rhs(x_andes, u, p)
        # a state with a zero time constant is algebraic in ANDES (no rate), and a degenerate
        # second-order filter's states follow its input there; ours are held: rate 0
        held = np.isnan(theirs) | np.isin(component.state_names, held_states(name, p))
        ours_out, theirs_out = output(ss, name, component, p, x_andes, u, model, i)
        _record(results, name, rate=np.abs(ours - theirs)[~held].max(), andes_rate=np.abs(theirs[~held]).max(),
                held_rate=np.abs(ours[held]).max(initial=0.0), output=abs(ours_out - theirs_out), at_limit=0.0)
        results[name]["at_limit"] += float(_at_limit(model, i))
    return results


def held_states(name: str, p) -> tuple:
    """Our states that a degenerate block holds unused (IEEEST's second-order filters with A2 = 0
    or A4 = 0) and that ANDES keeps as states following the input."""
    if name != "IEEEST":
        return ()
    return (("F1_x", "F1_y") if p.A2 == 0 else ()) + (("F2_x1", "F2_x2") if p.A4 == 0 else ())


def output(ss, name, component, p, x, u, model, i) -> tuple:
    """(ours, ANDES') of the device's main output: a machine's P (system base), an exciter's Efd,
    a governor's Pm (machine base), the stabiliser's Vss."""
    values = component.output_values(x, u, p)
    if name in MACHINES:
        return float(values[2]), _v(model.Pe, i)
    if name in GOVERNORS:
        return float(values[0]), _v(model.pout, i) * ss.config.mva / float(model.Sn.v[i])
    if name == "IEEEST":
        return float(values[0]), _v(model.vsout, i)
    return float(values[0]), _v(model.vout, i)


def _at_limit(model, i) -> bool:
    """Whether a non-windup limiter of ANDES' device i holds its state at a limit."""
    for block in model.discrete.values():
        if type(block).__name__ == "AntiWindup" and (block.zu[i] or block.zl[i]):
            return True
    return False


def compare_trajectories(case: str, fault_bus, tf: float = 3.0, h: float = 0.001, names=None,
                         tol: float = 1e-8) -> dict:
    """{model: {"devices", "state", "scale", "where"}}: ANDES runs the case with a three-phase
    fault at `fault_bus` from 1.0 s to 1.1 s at a fixed step h [s] to tf [s] (Newton tolerance
    tol); each device of our models (those in `names`, default all) is integrated alone (scipy's
    DOP853, rtol 1e-10) from ANDES' initial state under ANDES' recorded inputs (linear between its
    steps, restarted from ANDES' state after each of the fault's instants), and "state" is the
    largest difference from ANDES' states over the run (states ANDES treats as algebraic and
    degenerate filters' states left out: ours are held), "scale" the largest excursion of ANDES'
    states from their start, "where" (state name, time [s]) of the largest difference."""
    import andes
    from scipy.integrate import solve_ivp

    configure_andes_logging(andes, 40)
    ss = andes.load(andes.get_case(case), setup=False, no_output=True, default_config=True)
    ss.add("Fault", {"bus": fault_bus, "tf": 1.0, "tc": 1.1, "xf": 1e-4, "rf": 0.0})
    ss.setup()
    ss.PFlow.run()
    ss.TDS.config.update(tf=tf, tstep=h, fixt=1, shrinkt=0, tol=tol, no_tqdm=1)
    ss.TDS.run()
    ts = ss.dae.ts
    ts.unpack()
    series = {}
    for k in range(len(ts.t)):
        ss.dae.x[:] = ts.x[k]
        ss.dae.y[:] = ts.y[k]
        ss.vars_to_models()
        for name, _, p, u, x, model, i, _ in devices(ss):
            if names is None or name in names:
                if (name, i) not in series:
                    component = STANDARD_MODELS[name]
                    algebraic = np.isnan(_andes_rates(ss, model, component, i, name))
                    kept = ~(algebraic | np.isin(component.state_names, held_states(name, p)))
                entry = series.setdefault((name, i), dict(p=p, u=[], x=[], kept=kept if k == 0 else None))
                entry["u"].append(u)
                entry["x"].append(x)
    t = np.asarray(ts.t)
    events = (1.0, 1.1)
    results = {}
    for (name, i), entry in series.items():
        component, p = STANDARD_MODELS[name], entry["p"]
        us, xs = np.array(entry["u"]), np.array(entry["x"])
        state, worst, where = xs[0].copy(), 0.0, None
        kept = entry["kept"]
        bounds = [0.0, *events, tf]
        for start, stop in zip(bounds[:-1], bounds[1:]):
            inside = (t > start + 0.5 * h) & (t < stop - 0.5 * h)
            if not inside.any():
                continue
            tk, uk = t[inside], us[inside]

            def rhs(time, x, tk=tk, uk=uk):
                u = np.array([np.interp(time, tk, uk[:, j]) for j in range(uk.shape[1])])
                return component.rhs(x, u, p)

            # the first recorded point inside the segment restarts from ANDES' state there only at
            # the fault's instants (the inputs jump); elsewhere ours continues
            if start > 0.0:
                state = xs[inside][0].copy()
            sol = solve_ivp(rhs, (tk[0], tk[-1]), state, method="DOP853", rtol=1e-10, atol=1e-12, t_eval=tk,
                            max_step=0.01)
            miss = np.abs(sol.y.T - xs[inside])[:, kept]
            if miss.max() > worst:
                row, column = np.unravel_index(miss.argmax(), miss.shape)
                worst, where = float(miss.max()), (np.array(component.state_names)[kept][column], float(tk[row]))
            state = sol.y[:, -1]
        r = results.setdefault(name, dict(devices=0, state=0.0, scale=0.0, where=None))
        r["devices"] += 1
        if worst >= r["state"]:
            r["state"], r["where"] = worst, where
        r["scale"] = max(r["scale"], float(np.abs(xs - xs[0])[:, kept].max()))
    return results
