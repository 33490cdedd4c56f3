"""C source of a component's exact partial derivatives, generated from its one Python definition.

The component's equations run on `Dual` values: each carries its C expression and the C
expressions of its partial derivatives with respect to the states and inputs it depends on
(forward-mode differentiation, one statement per operation). No derivative is written by hand, and
a derivative that is structurally zero is never computed. A conditional (`DualMath.where` on a
comparison of Dual values, reference_models.piecewise.where) selects the value and the partial
derivatives of the branch taken: exact wherever the equations are differentiable.

Generated functions (n_x states, n_u inputs, columns ordered x then u):
    model_derivatives_jacobian(x, u, J)   J[i * (n_x + n_u) + j] = d f_i / d (x, u)_j
    model_outputs_jacobian(x, u, J)       J[i * (n_x + n_u) + j] = d g_i / d (x, u)_j
"""
from __future__ import annotations

import re

from reference_models.component import Component

from .c_equations import c_function, c_size, live_statements, p_argument, p_unused, symbolic
from .c_parameters import ParamCondition, ParamExpr, c_literal

_NAME = re.compile(r"\bd\d+\b")


class _Recorder:
    """Collects `const double dN = ...;` statements."""

    def __init__(self):
        self.lines: list[str] = []

    def emit(self, expression: str) -> str:
        name = f"d{len(self.lines)}"
        self.lines.append(f"    const double {name} = {expression};")
        return name


class Dual:
    """A double-valued C expression `code` with its partial derivatives `grads` {column: C expression}."""

    def __init__(self, code: str, grads: dict, recorder: _Recorder):
        self.code, self.grads, self.recorder = code, grads, recorder

    def _new(self, code: str, grads: dict) -> "Dual":
        return Dual(self.recorder.emit(code), {j: self.recorder.emit(g) for j, g in grads.items()}, self.recorder)

    def _lift(self, other) -> "Dual":
        return other if isinstance(other, Dual) else Dual(c_literal(other), {}, self.recorder)

    def __add__(self, other):
        o = self._lift(other)
        keys = sorted(self.grads.keys() | o.grads.keys())
        return self._new(f"{self.code} + {o.code}",
                         {j: " + ".join(g[j] for g in (self.grads, o.grads) if j in g) for j in keys})

    __radd__ = __add__

    def __sub__(self, other):
        return self + (-self._lift(other))

    def __rsub__(self, other):
        return self._lift(other) + (-self)

    def __mul__(self, other):
        o = self._lift(other)
        keys = sorted(self.grads.keys() | o.grads.keys())
        grads = {}
        for j in keys:
            terms = ([f"{self.grads[j]} * {o.code}"] if j in self.grads else []) + (
                [f"{self.code} * {o.grads[j]}"] if j in o.grads else [])
            grads[j] = " + ".join(terms)
        return self._new(f"{self.code} * {o.code}", grads)

    __rmul__ = __mul__

    def __truediv__(self, other):
        o = self._lift(other)
        value = self._new(f"{self.code} / {o.code}", {})
        keys = sorted(self.grads.keys() | o.grads.keys())
        grads = {}
        for j in keys:
            top = self.grads.get(j, "0.0") + (f" - {value.code} * {o.grads[j]}" if j in o.grads else "")
            grads[j] = self.recorder.emit(f"({top}) / {o.code}")
        return Dual(value.code, grads, self.recorder)

    def __rtruediv__(self, other):
        return self._lift(other) / self

    def __neg__(self):
        return self._new(f"-{self.code}", {j: f"-{g}" for j, g in self.grads.items()})

    def _compare(self, other, op) -> "DualCondition":
        return DualCondition(f"{self.code} {op} {self._lift(other).code}", self.recorder)

    __lt__ = lambda self, o: self._compare(o, "<")  # noqa: E731
    __le__ = lambda self, o: self._compare(o, "<=")  # noqa: E731
    __gt__ = lambda self, o: self._compare(o, ">")  # noqa: E731
    __ge__ = lambda self, o: self._compare(o, ">=")  # noqa: E731


class DualCondition:
    """A C comparison of Dual values (`code`), for `DualMath.where`."""

    def __init__(self, code: str, recorder: _Recorder):
        self.code, self.recorder = code, recorder

    def __bool__(self):
        raise TypeError("a traced comparison has no Python truth value: select with "
                        "reference_models.piecewise.where(m, condition, a, b)")


class DualMath:
    """The math namespace of Dual values: libm calls and their derivatives."""

    @staticmethod
    def sin(a: Dual) -> Dual:
        if isinstance(a, ParamExpr):
            return a.space.call("sin", a)
        c = a.recorder.emit(f"cos({a.code})")
        return a._new(f"sin({a.code})", {j: f"{c} * {g}" for j, g in a.grads.items()})

    @staticmethod
    def cos(a: Dual) -> Dual:
        if isinstance(a, ParamExpr):
            return a.space.call("cos", a)
        s = a.recorder.emit(f"sin({a.code})")
        return a._new(f"cos({a.code})", {j: f"-{s} * {g}" for j, g in a.grads.items()})

    @staticmethod
    def exp(a: Dual) -> Dual:
        if isinstance(a, ParamExpr):
            return a.space.call("exp", a)
        value = a._new(f"exp({a.code})", {})
        return Dual(value.code, {j: a.recorder.emit(f"{value.code} * {g}") for j, g in a.grads.items()}, a.recorder)

    @staticmethod
    def sqrt(a: Dual) -> Dual:
        if isinstance(a, ParamExpr):
            return a.space.call("sqrt", a)
        value = a._new(f"sqrt({a.code})", {})
        return Dual(value.code, {j: a.recorder.emit(f"{g} / (2.0 * {value.code})") for j, g in a.grads.items()},
                    a.recorder)

    @staticmethod
    def where(condition, a, b):
        """a where condition holds, else b, with the partial derivatives of the branch taken (a
        condition on parameters alone: a conditional on them)."""
        if isinstance(condition, ParamCondition):
            duals = [v for v in (a, b) if isinstance(v, Dual)]
            if not duals:
                return condition.space.select(condition, a, b)
            recorder = duals[0].recorder
        elif not isinstance(condition, DualCondition):
            return a if condition else b
        else:
            recorder = condition.recorder
        a, b = (v if isinstance(v, Dual) else Dual(c_literal(v), {}, recorder) for v in (a, b))
        keys = sorted(a.grads.keys() | b.grads.keys())
        return a._new(f"({condition.code}) ? {a.code} : {b.code}",
                      {j: f"({condition.code}) ? {a.grads.get(j, '0.0')} : {b.grads.get(j, '0.0')}" for j in keys})


def c_jacobian_function(name: str, fn, component: Component, params, n_rows: int, doc: str) -> str:
    """`static void name(const double x[], const double u[], [const double p[],] double J[])`: the
    row-major Jacobian [n_rows, n_x + n_u] of fn(x, u, params, m) with respect to (x, u) (p: where
    params is a ParameterSpace, c_equations)."""
    recorder = _Recorder()
    n_x, n_u = component.n_states, component.n_inputs
    x = [Dual(f"x[{i}]", {i: "1.0"}, recorder) for i in range(n_x)]
    u = [Dual(f"u[{i}]", {n_x + i: "1.0"}, recorder) for i in range(n_u)]
    results = fn(x, u, symbolic(params), DualMath)
    if len(results) != n_rows:
        raise ValueError(f"{name}: expected {n_rows} results, got {len(results)}")
    cols = n_x + n_u
    stores = []
    for i, r in enumerate(results):
        grads = r.grads if isinstance(r, Dual) else {}
        stores += [f"    J[{i * cols + j}] = {grads.get(j, '0.0')};" for j in range(cols)]
    # a value whose only use was its own derivative is dropped
    body = live_statements(recorder.lines, stores, _NAME) + stores
    return (f"/* {doc}: J[i * {cols} + j] = d out_i / d (x, u)_j */\n"
            f"static void {name}(const double x[{c_size(n_x)}], const double u[{n_u}], {p_argument(params)}"
            f"double J[{c_size(n_rows) * cols}])\n{{\n"
            + "\n".join(["    (void)x;", "    (void)u;"] + p_unused(params) + body) + "\n}\n")


def jacobians_c_source(component: Component, params) -> str:
    """C source with model_derivatives_jacobian and model_outputs_jacobian of `component` for `params`."""
    header = (f"/* Generated by opfmu from the {component.name} component definition (forward-mode "
              f"derivatives); do not edit. Columns: ({', '.join(component.state_names + component.input_names)}) */\n"
              "#include <math.h>\n\n")
    rhs = c_jacobian_function("model_derivatives_jacobian", component.derivatives, component, params,
                              component.n_states, f"{component.name} d(dx/dt)/d(x, u)")
    outs = c_jacobian_function("model_outputs_jacobian", component.output_equations, component, params,
                               len(component.outputs), f"{component.name} d(outputs)/d(x, u)")
    return header + rhs + "\n" + outs


def start_equations_c_source(component: Component, params) -> str:
    """C source of `model_start_equations(x, u, p, r)` and `component_start_jacobian(x, u, p, J)`
    (model.h) for a component with start equations of its own (Component.start_equations), "" for
    one without: its start solves its rates."""
    if component.start_equations is None:
        return ""
    n_x, n_u = component.n_states, component.n_inputs
    residuals = c_function("model_start_equations", component.start_equations, component, params,
                           [f"start equation of {n}" for n in component.state_names],
                           f"{component.name} start equations", linkage="OPFMU_INTERNAL")
    jacobian = c_jacobian_function("start_equations_jacobian", component.start_equations, component, params, n_x,
                                   f"{component.name} d(start equations)/d(x, u)")
    return (residuals + "\n" + jacobian + "\n"
            f"void component_start_jacobian(const double x[{c_size(n_x)}], const double u[{n_u}], const double p[], "
            f"double J[{c_size(n_x) * (n_x + n_u)}])\n"
            "{\n    start_equations_jacobian(x, u, p, J);\n}\n")
