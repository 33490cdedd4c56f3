"""C source of a component's equations, generated from its one Python definition.

A component's equations are written against a math namespace; running them on `Traced` values
records every arithmetic step as a C statement, so the C code computes exactly the expressions scipy
and torch use. Given a parameter object, the parameters are baked in as literals (shortest
round-trip repr, so no digit is lost); given a ParameterSpace (fmu_export.c_parameters), they are
read from the FMU instance's parameter array p, and every generated function takes p after u. Each traced value also knows which inputs it depends on, which gives the model description
its direct input dependencies. A comparison of traced values is a `Condition` (a C comparison), which
`CMath.where` turns into a conditional expression (reference_models.piecewise.where); it has no
Python truth value, so an equation that branches with `if` on a traced value fails loudly.

The conditions of the right-hand side are its switching functions (`switching_c_source`): for the
comparison `a op b`, g = a - b, and the branch each `where` takes is its mode (the comparison's
truth). The native reference FMU integrates with the modes locked (the right-hand side smooth within
a solver step) and locates the instant a mode changes (fmu_export/c/dopri5.c, docs/fmu.md). A
component's reset (`reset_c_source`: states placed on the non-windup limits they are pushed beyond)
is applied where it (re)locks the modes.
"""
from __future__ import annotations

import re

from reference_models.component import Component

from .c_parameters import Arithmetic, ParamCondition, ParamExpr, ParameterSpace, c_literal

_NAME = re.compile(r"\bt\d+\b")


class _Recorder:
    """Collects `const double tN = ...;` statements."""

    def __init__(self, locked: bool = False):
        self.lines: list[str] = []
        self.conditions: list["Condition"] = []  # the distinct conditions `where` selected on, in order
        self.locked = locked  # `where` selects on mode[k] (the locked branch) instead of the comparison

    def mode(self, condition: "Condition") -> int:
        """The index k of a condition among the distinct ones recorded (by its C code)."""
        codes = [c.code for c in self.conditions]
        if condition.code not in codes:
            self.conditions.append(condition)
            return len(self.conditions) - 1
        return codes.index(condition.code)

    def emit(self, expression: str, inputs: frozenset) -> "Traced":
        name = f"t{len(self.lines)}"
        self.lines.append(f"    const double {name} = {expression};")
        return Traced(name, self, inputs)


class Traced(Arithmetic):
    """A double-valued C expression; arithmetic on it records C statements. `inputs`: the indices
    of the component inputs the value depends on."""

    def __init__(self, code: str, recorder: _Recorder, inputs: frozenset = frozenset()):
        self.code, self.recorder, self.inputs = code, recorder, inputs

    def _binary(self, other, op, swap=False):
        traced = isinstance(other, Traced)
        rhs = other.code if traced else c_literal(other)
        a, b = (rhs, self.code) if swap else (self.code, rhs)
        return self.recorder.emit(f"{a} {op} {b}", self.inputs | (other.inputs if traced else frozenset()))

    def __neg__(self):
        return self.recorder.emit(f"-{self.code}", self.inputs)

    def _compare(self, other, op):
        traced = isinstance(other, Traced)
        rhs = other.code if traced else c_literal(other)
        inputs = self.inputs | (other.inputs if traced else frozenset())
        return Condition(f"{self.code} {op} {rhs}", self.recorder, inputs, f"{self.code} - {rhs}")

    __lt__ = lambda self, o: self._compare(o, "<")  # noqa: E731
    __le__ = lambda self, o: self._compare(o, "<=")  # noqa: E731
    __gt__ = lambda self, o: self._compare(o, ">")  # noqa: E731
    __ge__ = lambda self, o: self._compare(o, ">=")  # noqa: E731


class Condition:
    """A C comparison of traced values `a op b` (`code`), for `CMath.where`; `inputs` as Traced's;
    `switching`: the C expression a - b (its switching function)."""

    def __init__(self, code: str, recorder: _Recorder, inputs: frozenset, switching: str):
        self.code, self.recorder, self.inputs, self.switching = code, recorder, inputs, switching

    def __bool__(self):
        raise TypeError("a traced comparison has no Python truth value: select with "
                        "reference_models.piecewise.where(m, condition, a, b)")


def c_size(n: int) -> int:
    """The declared size of a C array of n values: at least 1, as C requires (a component without
    states declares one unused state)."""
    return max(int(n), 1)


class CMath:
    """The math namespace of traced values: each function becomes a call to C's libm."""

    @staticmethod
    def _call(name, arg):
        if isinstance(arg, ParamExpr):
            return arg.space.call(name, arg)
        return arg.recorder.emit(f"{name}({arg.code})", arg.inputs)

    sin = staticmethod(lambda a: CMath._call("sin", a))
    cos = staticmethod(lambda a: CMath._call("cos", a))
    exp = staticmethod(lambda a: CMath._call("exp", a))
    sqrt = staticmethod(lambda a: CMath._call("sqrt", a))

    @staticmethod
    def where(condition, a, b):
        """a where condition holds, else b: C's conditional expression (a number condition: a or b; a
        condition on parameters alone: a conditional on them, no switching function)."""
        if isinstance(condition, ParamCondition):
            traced = [v for v in (a, b) if isinstance(v, Traced)]
            if not traced:
                return condition.space.select(condition, a, b)
            inputs = frozenset().union(*(v.inputs for v in traced))
            return traced[0].recorder.emit(f"({condition.code}) ? {_result(a)} : {_result(b)}",
                                           inputs)
        if not isinstance(condition, Condition):
            return a if condition else b
        code = [_result(v) for v in (a, b)]
        inputs = condition.inputs.union(*(v.inputs for v in (a, b) if isinstance(v, Traced)))
        k = condition.recorder.mode(condition)
        select = f"mode[{k}]" if condition.recorder.locked else f"({condition.code})"
        return condition.recorder.emit(f"{select} ? {code[0]} : {code[1]}", inputs)


def _result(value) -> str:
    """The C expression of a value: a traced value's name, a number or a parameter expression."""
    return value.code if isinstance(value, Traced) else c_literal(value)


def symbolic(params):
    """The parameter object the equations run on: a ParameterSpace's symbolic one, else params."""
    return params.symbolic if isinstance(params, ParameterSpace) else params


def p_argument(params) -> str:
    """The parameter array argument of a generated function: `const double p[], ` where `params`
    is a ParameterSpace (the parameters read from the instance), else none (baked in)."""
    return "const double p[], " if isinstance(params, ParameterSpace) else ""


def p_unused(params) -> list:
    """The statement that marks the parameter array used (a function may read none of it)."""
    return ["    (void)p;"] if isinstance(params, ParameterSpace) else []


def _trace(fn, component: Component, params, locked: bool = False, recorder: _Recorder | None = None):
    """(statements, results) of fn(x, u, params, CMath) on the C arrays x[], u[] (locked: every
    `where` selects on mode[k]); params: a parameter object (baked in) or a ParameterSpace (read
    from p[])."""
    recorder = recorder or _Recorder(locked)
    x = [Traced(f"x[{i}]", recorder) for i in range(component.n_states)]
    u = [Traced(f"u[{i}]", recorder, frozenset({i})) for i in range(component.n_inputs)]
    return recorder.lines, fn(x, u, symbolic(params), CMath)


def c_function(name: str, fn, component: Component, params, outputs: list[str], doc: str,
               linkage: str = "static") -> str:
    """`<linkage> void name(const double x[], const double u[], [const double p[],] double out[])`
    computing fn (p: where params is a ParameterSpace)."""
    lines, results = _trace(fn, component, params)
    body = p_unused(params) + lines + [f"    out[{i}] = {_result(r)};" for i, r in enumerate(results)]
    return (f"/* {_comment(doc)}: out = ({_comment(', '.join(outputs))}) */\n"
            f"{linkage} void {name}(const double x[{c_size(component.n_states)}], "
            f"const double u[{component.n_inputs}], {p_argument(params)}double out[{c_size(len(outputs))}])\n{{\n"
            + "\n".join(body) + "\n}\n")


def output_input_dependencies(component: Component, params) -> list[tuple]:
    """Per derived output, the input names it depends on directly (from the traced equations)."""
    _, results = _trace(component.output_equations, component, params)
    return [tuple(component.input_names[i] for i in sorted(r.inputs)) if isinstance(r, Traced) else ()
            for r in results]


def parameter_space(component: Component, params, trained: bool = False) -> ParameterSpace:
    """The ParameterSpace of `component` with parameters `params` (a checked parameter object)
    after its right-hand side, derived outputs and reset were traced on it: its structural
    predicates known (ParameterSpace.structure, the identity of an FMU built for it). trained: a
    surrogate's (every value fixed). A component whose equations do not run on symbolic parameters
    (they build a parameter object of their own from them) gets a space with every value fixed."""
    space = ParameterSpace(component, params, "trained" if trained else None)
    try:
        for fn in (component.derivatives, component.output_equations, component.reset):
            if fn is not None:
                _trace(fn, component, space)
    except (TypeError, ValueError):
        return ParameterSpace(component, params, "baked")
    return space


def _comment(text: str) -> str:
    """text safe inside a C block comment, on one line."""
    return " ".join(text.split()).replace("*/", "* /")


def equations_c_source(component: Component, params, linkage: str = "static") -> str:
    """C source with `model_derivatives(x, u, dx)` and `model_outputs(x, u, y)` of `component`
    for parameters `params` (a parameter object: baked in; a ParameterSpace: read from the array p,
    `model_derivatives(x, u, p, dx)`, `model_outputs(x, u, p, y)`); `linkage` prefixes both
    definitions (static: for one translation unit; a visibility attribute macro: for a library of
    several)."""
    states, inputs = _comment(", ".join(component.state_names)), _comment(", ".join(component.input_names))
    if isinstance(params, ParameterSpace):
        listing = "p = (" + ", ".join(params.names) + ", then the derived parameters)"
    else:
        listing = f"parameters: {params.to_dict()}"
    header = (f"/* Generated by opfmu from the {_comment(component.name)} component definition; do not edit.\n"
              f"   x = ({states}), u = ({inputs}); {_comment(listing)} */\n"
              "#include <math.h>\n\n")
    deriv = c_function("model_derivatives", component.derivatives, component, params,
                       [f"d{n}/dt" for n in component.state_names], f"{component.name} right-hand side dx/dt", linkage)
    outs = c_function("model_outputs", component.output_equations, component, params,
                      list(component.output_names), f"{component.name} derived outputs", linkage)
    return header + deriv + "\n" + outs


def reset_c_source(component: Component, params, linkage: str = "static") -> str:
    """C source of `model_reset(x, u, out)`: the states after the component's limit resets
    (Component.reset: a state at or beyond a non-windup limit while its unlimited rate pushes
    outward placed on the limit), its conditions compared directly (not switching functions of the
    right-hand side); "" for a component without a reset."""
    if component.reset is None:
        return ""
    lines, results = _trace(component.reset, component, params)
    stores = [f"    out[{i}] = {_result(r)};" for i, r in enumerate(results)]
    n_x, n_u = component.n_states, component.n_inputs
    return (f"/* {_comment(component.name)} states after the resets of its non-windup limits: out = "
            f"({_comment(', '.join(component.state_names))}) */\n"
            f"{linkage} void model_reset(const double x[{n_x}], const double u[{n_u}], {p_argument(params)}"
            f"double out[{n_x}])\n{{\n"
            + "\n".join(["    (void)u;"] + p_unused(params) + live_statements(lines, stores) + stores) + "\n}\n")


def switching_conditions(component: Component, params) -> list:
    """The distinct conditions (`Condition`) the right-hand side selects on, in the order of their
    modes: its switching functions."""
    recorder = _Recorder()
    _trace(component.derivatives, component, params, recorder=recorder)
    return recorder.conditions


def live_statements(lines: list[str], uses: list[str], names: re.Pattern = _NAME) -> list[str]:
    """The traced statements `lines` ("type name = expression") that `uses` need, in order; `names`
    matches the traced values' names."""
    needed = set(names.findall(" ".join(uses)))
    kept = []
    for line in reversed(lines):
        name, _, expression = line.partition(" = ")
        if name.split()[-1] in needed:
            kept.append(line)
            needed.update(names.findall(expression))
    return kept[::-1]


def switching_c_source(component: Component, params, linkage: str = "static") -> tuple:
    """(n_g, C source) of the right-hand side's switching functions: n_g, the number of distinct
    conditions its `where`s select on; with n_g > 0 the source defines
        model_switching(x, u, [p,] g, mode)        g[k] = a - b and mode[k] = (a op b) of condition k
        model_derivatives_locked(x, u, [p,] mode, dx)   dx/dt with each `where` taking the branch mode[k]
    (model_derivatives_locked with mode from model_switching at the same x, u is model_derivatives);
    with n_g = 0, an empty source."""
    recorder = _Recorder()
    lines, _ = _trace(component.derivatives, component, params, recorder=recorder)
    conditions = recorder.conditions
    n, n_x, n_u = len(conditions), component.n_states, component.n_inputs
    if n == 0:
        return 0, ""
    stores = [f"    g[{k}] = {c.switching};\n    mode[{k}] = {c.code};" for k, c in enumerate(conditions)]
    listing = _comment("; ".join(f"{k}: {c.code}" for k, c in enumerate(conditions)))
    switching = (f"/* {_comment(component.name)} switching functions of the right-hand side: g[k] = a - b of its "
                 f"condition k (a op b), mode[k] = the condition's truth ({listing}) */\n"
                 f"{linkage} void model_switching(const double x[{n_x}], const double u[{n_u}], {p_argument(params)}"
                 f"double g[{n}], int mode[{n}])\n{{\n    (void)x;\n    (void)u;\n"
                 + "\n".join(p_unused(params) + live_statements(lines, stores) + stores) + "\n}\n")
    lines, results = _trace(component.derivatives, component, params, locked=True)
    body = p_unused(params) + lines + [f"    dx[{i}] = {_result(r)};" for i, r in enumerate(results)]
    locked = (f"/* {_comment(component.name)} right-hand side dx/dt with condition k's branch locked to mode[k] */\n"
              f"{linkage} void model_derivatives_locked(const double x[{n_x}], const double u[{n_u}], "
              f"{p_argument(params)}const int mode[{n}], double dx[{n_x}])\n{{\n    (void)mode;\n"
              + "\n".join(body) + "\n}\n")
    return n, switching + "\n" + locked
