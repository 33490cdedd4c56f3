"""C source of a component's equations, generated from its one Python definition.

A component's equations are written against a math namespace; running them on `Traced` values
records every arithmetic step as a C statement, so the C code computes exactly the expressions scipy
and torch use, with the parameters baked in as literals (shortest round-trip repr, so no digit is
lost). Each traced value also knows which inputs it depends on, which gives the model description
its direct input dependencies. A comparison of traced values is a `Condition` (a C comparison), which
`CMath.where` turns into a conditional expression (reference_models.piecewise.where); it has no
Python truth value, so an equation that branches with `if` on a traced value fails loudly.
"""
from __future__ import annotations

from reference_models.component import Component


class _Recorder:
    """Collects `const double tN = ...;` statements."""

    def __init__(self):
        self.lines: list[str] = []

    def emit(self, expression: str, inputs: frozenset) -> "Traced":
        name = f"t{len(self.lines)}"
        self.lines.append(f"    const double {name} = {expression};")
        return Traced(name, self, inputs)


class Traced:
    """A double-valued C expression; arithmetic on it records C statements. `inputs`: the indices
    of the component inputs the value depends on."""

    def __init__(self, code: str, recorder: _Recorder, inputs: frozenset = frozenset()):
        self.code, self.recorder, self.inputs = code, recorder, inputs

    def _binary(self, other, op, swap=False):
        traced = isinstance(other, Traced)
        rhs = other.code if traced else _literal(other)
        a, b = (rhs, self.code) if swap else (self.code, rhs)
        return self.recorder.emit(f"{a} {op} {b}", self.inputs | (other.inputs if traced else frozenset()))

    __add__ = lambda self, o: self._binary(o, "+")  # noqa: E731
    __radd__ = lambda self, o: self._binary(o, "+", True)  # noqa: E731
    __sub__ = lambda self, o: self._binary(o, "-")  # noqa: E731
    __rsub__ = lambda self, o: self._binary(o, "-", True)  # noqa: E731
    __mul__ = lambda self, o: self._binary(o, "*")  # noqa: E731
    __rmul__ = lambda self, o: self._binary(o, "*", True)  # noqa: E731
    __truediv__ = lambda self, o: self._binary(o, "/")  # noqa: E731
    __rtruediv__ = lambda self, o: self._binary(o, "/", True)  # noqa: E731

    def __neg__(self):
        return self.recorder.emit(f"-{self.code}", self.inputs)

    def _compare(self, other, op):
        traced = isinstance(other, Traced)
        rhs = other.code if traced else _literal(other)
        return Condition(f"{self.code} {op} {rhs}", self.recorder, self.inputs | (other.inputs if traced else frozenset()))

    __lt__ = lambda self, o: self._compare(o, "<")  # noqa: E731
    __le__ = lambda self, o: self._compare(o, "<=")  # noqa: E731
    __gt__ = lambda self, o: self._compare(o, ">")  # noqa: E731
    __ge__ = lambda self, o: self._compare(o, ">=")  # noqa: E731


class Condition:
    """A C comparison of traced values (`code`), for `CMath.where`; `inputs` as Traced's."""

    def __init__(self, code: str, recorder: _Recorder, inputs: frozenset):
        self.code, self.recorder, self.inputs = code, recorder, inputs

    def __bool__(self):
        raise TypeError("a traced comparison has no Python truth value: select with "
                        "reference_models.piecewise.where(m, condition, a, b)")


def _literal(value: float) -> str:
    text = repr(float(value))
    return f"({text})" if text.startswith("-") else text


class CMath:
    """The math namespace of traced values: each function becomes a call to C's libm."""

    @staticmethod
    def _call(name, arg):
        return arg.recorder.emit(f"{name}({arg.code})", arg.inputs)

    sin = staticmethod(lambda a: CMath._call("sin", a))
    cos = staticmethod(lambda a: CMath._call("cos", a))
    exp = staticmethod(lambda a: CMath._call("exp", a))
    sqrt = staticmethod(lambda a: CMath._call("sqrt", a))

    @staticmethod
    def where(condition, a, b):
        """a where condition holds, else b: C's conditional expression (a number condition: a or b)."""
        if not isinstance(condition, Condition):
            return a if condition else b
        code = [v.code if isinstance(v, Traced) else _literal(v) for v in (a, b)]
        inputs = condition.inputs.union(*(v.inputs for v in (a, b) if isinstance(v, Traced)))
        return condition.recorder.emit(f"({condition.code}) ? {code[0]} : {code[1]}", inputs)


def _trace(fn, component: Component, params):
    """(statements, results) of fn(x, u, params, CMath) on the C arrays x[], u[]."""
    recorder = _Recorder()
    x = [Traced(f"x[{i}]", recorder) for i in range(component.n_states)]
    u = [Traced(f"u[{i}]", recorder, frozenset({i})) for i in range(component.n_inputs)]
    return recorder.lines, fn(x, u, params, CMath)


def c_function(name: str, fn, component: Component, params, outputs: list[str], doc: str,
               linkage: str = "static") -> str:
    """`<linkage> void name(const double x[], const double u[], double out[])` computing fn."""
    lines, results = _trace(fn, component, params)
    body = lines + [f"    out[{i}] = {r.code if isinstance(r, Traced) else _literal(r)};"
                    for i, r in enumerate(results)]
    return (f"/* {_comment(doc)}: out = ({_comment(', '.join(outputs))}) */\n"
            f"{linkage} void {name}(const double x[{component.n_states}], const double u[{component.n_inputs}], "
            f"double out[{len(outputs)}])\n{{\n" + "\n".join(body) + "\n}\n")


def output_input_dependencies(component: Component, params) -> list[tuple]:
    """Per derived output, the input names it depends on directly (from the traced equations)."""
    _, results = _trace(component.output_equations, component, params)
    return [tuple(component.input_names[i] for i in sorted(r.inputs)) if isinstance(r, Traced) else ()
            for r in results]


def _comment(text: str) -> str:
    """text safe inside a C block comment, on one line."""
    return " ".join(text.split()).replace("*/", "* /")


def equations_c_source(component: Component, params, linkage: str = "static") -> str:
    """C source with `model_derivatives(x, u, dx)` and `model_outputs(x, u, y)` of `component`
    for parameters `params`; `linkage` prefixes both definitions (static: for one translation unit;
    a visibility attribute macro: for a library of several)."""
    states, inputs = _comment(", ".join(component.state_names)), _comment(", ".join(component.input_names))
    header = (f"/* Generated by opfmu from the {_comment(component.name)} component definition; do not edit.\n"
              f"   x = ({states}), u = ({inputs}); parameters: {_comment(str(params.to_dict()))} */\n"
              "#include <math.h>\n\n")
    deriv = c_function("model_derivatives", component.derivatives, component, params,
                       [f"d{n}/dt" for n in component.state_names], f"{component.name} right-hand side dx/dt", linkage)
    outs = c_function("model_outputs", component.output_equations, component, params,
                      list(component.output_names), f"{component.name} derived outputs", linkage)
    return header + deriv + "\n" + outs
