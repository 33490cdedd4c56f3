"""A component's parameters as values of the generated C: read from the FMU instance, not baked in.

A `ParameterSpace` holds one FMU build's parameters. Its `symbolic` object is the component's
parameter object with every field a `ParamExpr`: the C expression `p[i]` (the instance's parameter
array) with the value the FMU is built for. The equations run on it as on numbers: arithmetic on
parameters makes derived parameters (a sum of fractions, a base ratio), each a slot of `p` after the
component's own, computed once whenever a parameter is set (`model_derive`, generated); the
tracers of c_equations and c_derivatives take a ParamExpr as a constant of the C code.

What the equations decide in Python on a parameter's value is found as it happens:
* the truth of a comparison (`if p.T1 > 0`, `S12 != 0`, `min`, `max`) is recorded as a structural
  predicate with the outcome seen (T1 > 0 held);
* a value forced into a Python number (`float(p.T)`, `math.sqrt(p.S10 ...)`) fixes every parameter
  it reads at its value (the predicate T = value).
The generated C holds for every parameter set under which each predicate has the outcome seen, and
only for those: the FMU refuses a set where one does not (`model_check_parameters`), and a build's
identity (`structure`) is its predicates with their outcomes. A comparison `where` selects on
(reference_models.piecewise.where) stays a C conditional and is no predicate.

The component's own checks (Parameters.check) are traced too, in a mode where a comparison's truth
is the value's and nothing is recorded: `low <= p.X <= high` (check_ranges) becomes the range of X
(declared min/max and refused outside), and a `require` whose condition is one comparison of
parameters (VMIN < VMAX, xq2 == xd2) becomes a C check. What check() decides otherwise (a
disjunction, membership in a set, a value forced into a number) only Python checks: `python_checks`
lists those rules.

A space with its values `fixed` has no symbolic parameters: its equations keep the values as
literals, and the FMU refuses any other value of any parameter: a surrogate's ("trained": an
operator is trained for one parameter set), and a component whose equations cannot run on symbolic
parameters ("baked": they build a parameter object of their own from them, which takes numbers only;
c_equations.parameter_space).
"""
from __future__ import annotations

import math
import numbers
import re
from dataclasses import dataclass, fields

_NEGATED = {"<": ">=", "<=": ">", ">": "<=", ">=": "<", "==": "!=", "!=": "=="}
_COMPARE = {"<": lambda a, b: a < b, "<=": lambda a, b: a <= b, ">": lambda a, b: a > b,
            ">=": lambda a, b: a >= b, "==": lambda a, b: a == b, "!=": lambda a, b: a != b}
_LIBM = {"sin": math.sin, "cos": math.cos, "exp": math.exp, "sqrt": math.sqrt, "fabs": abs}
TRAINED_TOLERANCE = 1e-9  # relative: a surrogate takes a parameter this close to its trained value
_RANGE_RULE = re.compile(r"lie in \[[^\]]*\]\s*(\S*)")


def c_literal(value) -> str:
    """A number as a C double literal (shortest round trip; infinities as INFINITY), or a
    ParamExpr's C expression."""
    if isinstance(value, ParamExpr):
        return value.code
    value = float(value)
    if math.isinf(value):
        return "INFINITY" if value > 0 else "(-INFINITY)"
    text = repr(value)
    return f"({text})" if text.startswith("-") else text


def _text(value) -> str:
    return value.text if isinstance(value, ParamExpr) else f"{float(value):.17g}"


def _value(value) -> float:
    return value.value if isinstance(value, ParamExpr) else float(value)


def _reads(*values) -> frozenset:
    return frozenset().union(*(v.reads for v in values if isinstance(v, ParamExpr)))


def _operand(value) -> bool:
    return isinstance(value, ParamExpr) or (isinstance(value, numbers.Real) and not isinstance(value, bool))


class Arithmetic:
    """The arithmetic operators of a traced value, each its class's `_binary(other, op, swap)`."""

    __add__ = lambda self, o: self._binary(o, "+")  # noqa: E731
    __radd__ = lambda self, o: self._binary(o, "+", True)  # noqa: E731
    __sub__ = lambda self, o: self._binary(o, "-")  # noqa: E731
    __rsub__ = lambda self, o: self._binary(o, "-", True)  # noqa: E731
    __mul__ = lambda self, o: self._binary(o, "*")  # noqa: E731
    __rmul__ = lambda self, o: self._binary(o, "*", True)  # noqa: E731
    __truediv__ = lambda self, o: self._binary(o, "/")  # noqa: E731
    __rtruediv__ = lambda self, o: self._binary(o, "/", True)  # noqa: E731


class ParamExpr(Arithmetic):
    """A parameter or a value derived from parameters: `code` its C expression (a slot p[k]),
    `text` a readable form, `value` its value for the built parameters, `reads` the indices of the
    component's parameters it depends on."""

    __array_ufunc__ = None  # numpy defers to the reflected operators (Arithmetic's)

    def __init__(self, space: "ParameterSpace", code: str, text: str, value: float, reads: frozenset):
        self.space, self.code, self.text, self.value, self.reads = space, code, text, value, reads

    def __deepcopy__(self, memo):
        return self

    __hash__ = object.__hash__

    def _binary(self, other, op, swap=False):
        if not _operand(other):
            return NotImplemented
        a, b = (other, self) if swap else (self, other)
        values = _value(a), _value(b)
        if op == "pow":
            return self.space.derive(f"pow({c_literal(a)}, {c_literal(b)})", f"{_text(a)}^{_text(b)}",
                                     values[0] ** values[1], _reads(a, b))
        value = {"+": values[0] + values[1], "-": values[0] - values[1], "*": values[0] * values[1],
                 "/": values[0] / values[1] if values[1] != 0 else math.copysign(math.inf, values[0])}[op]
        return self.space.derive(f"{c_literal(a)} {op} {c_literal(b)}", f"({_text(a)} {op} {_text(b)})", value,
                                 _reads(a, b))

    __pow__ = lambda self, o: self._binary(o, "pow")  # noqa: E731
    __rpow__ = lambda self, o: self._binary(o, "pow", True)  # noqa: E731

    def __neg__(self):
        return self.space.derive(f"-{self.code}", f"-{self.text}", -self.value, self.reads)

    def __pos__(self):
        return self

    def __abs__(self):
        return self.space.call("fabs", self)

    def _compare(self, other, op):
        if not _operand(other):
            return NotImplemented
        return ParamCondition(self, op, other)

    __lt__ = lambda self, o: self._compare(o, "<")  # noqa: E731
    __le__ = lambda self, o: self._compare(o, "<=")  # noqa: E731
    __gt__ = lambda self, o: self._compare(o, ">")  # noqa: E731
    __ge__ = lambda self, o: self._compare(o, ">=")  # noqa: E731
    __eq__ = lambda self, o: self._compare(o, "==")  # noqa: E731
    __ne__ = lambda self, o: self._compare(o, "!=")  # noqa: E731

    def __float__(self):
        return self.space.forced(self)

    def __int__(self):
        return int(self.space.forced(self))

    def __format__(self, spec):  # a message's text (check()'s rules), no decision
        return format(self.value, spec)

    def __bool__(self):
        return bool(self.space.forced(self))

    def __repr__(self):
        return f"ParamExpr({self.text} = {self.value!r})"


class ParamCondition:
    """A comparison `left op right` of parameters (at least one a ParamExpr): a C condition `code`
    for a `where`; its Python truth records a structural predicate (ParameterSpace.decided)."""

    def __init__(self, left, op: str, right):
        self.left, self.op, self.right = left, op, right
        self.space = (left if isinstance(left, ParamExpr) else right).space
        self.code = f"{c_literal(left)} {op} {c_literal(right)}"
        self.text = f"{_text(left)} {op} {_text(right)}"
        self.value = _COMPARE[op](_value(left), _value(right))
        self.reads = _reads(left, right)

    def negated_text(self) -> str:
        return f"{_text(self.left)} {_NEGATED[self.op]} {_text(self.right)}"

    def __bool__(self):
        return self.space.decided(self)


@dataclass(frozen=True)
class Rule:
    """A check of the generated C: `code` (a C condition on p) must hold, else the FMU refuses
    with `message` (a printf format whose %.16g take the values of the parameters `shown`, by
    index). kind: range, structural, relation or trained; reads: the parameters it depends on."""

    kind: str
    code: str
    message: str
    shown: tuple
    reads: frozenset


class ParameterSpace:
    """The parameters of one FMU build of `component` (see the module docstring); `params` a
    checked parameter object; fixed: None (symbolic), "trained" (a surrogate's) or "baked" (every
    value fixed, the equations on literals)."""

    def __init__(self, component, params, fixed: str | None = None):
        self.component, self.params, self.fixed = component, params, fixed
        self.names = tuple(f.name for f in fields(component.params_type))
        self.values = tuple(float(getattr(params, n)) for n in self.names)
        self.derived: list[tuple] = []  # (C expression, value) of each derived slot, in order
        self._slots: dict[str, ParamExpr] = {}
        self.predicates: dict[str, tuple] = {}  # C code -> (ParamCondition or forced value, outcome)
        self.checking = False
        self._pending: list = []
        self._opaque = False
        self.ranges: dict[int, tuple] = {}  # parameter index -> (low, high, unit)
        self.relations: list[tuple] = []  # (require's parameter name, ParamCondition)
        self.python_checks: list[str] = []
        self.base = tuple(ParamExpr(self, f"p[{i}]", n, v, frozenset({i}))
                          for i, (n, v) in enumerate(zip(self.names, self.values)))
        self.symbolic = params if fixed else _symbolic_params(component.params_type, self)
        if fixed:
            self.ranges = ParameterSpace(component, params).ranges
        else:
            self._trace_checks()

    @property
    def n(self) -> int:
        return len(self.names)

    @property
    def size(self) -> int:
        """The declared size of the instance's parameter array (parameters, then derived; at least 1)."""
        return max(self.n + len(self.derived), 1)

    # what the equations do with parameters

    def derive(self, expression: str, text: str, value: float, reads: frozenset) -> ParamExpr:
        """The derived parameter of that C expression (one slot per distinct expression)."""
        if expression not in self._slots:
            self._slots[expression] = ParamExpr(self, f"p[{self.n + len(self.derived)}]", text, value, reads)
            self.derived.append((expression, value))
        return self._slots[expression]

    def call(self, name: str, arg: ParamExpr) -> ParamExpr:
        """libm's `name` of a parameter expression: a derived parameter."""
        return self.derive(f"{name}({arg.code})", f"{name}({arg.text})", _LIBM[name](arg.value), arg.reads)

    def select(self, condition: ParamCondition, a, b) -> ParamExpr:
        """a where the condition on parameters holds, else b: a derived parameter."""
        return self.derive(f"({condition.code}) ? {c_literal(a)} : {c_literal(b)}",
                           f"({condition.text} ? {_text(a)} : {_text(b)})",
                           _value(a) if condition.value else _value(b), _reads(a, b) | condition.reads)

    def decided(self, condition: ParamCondition) -> bool:
        """The Python truth of a comparison of parameters: a structural predicate while the
        equations run, a step of a rule while check() runs."""
        if self.checking:
            self._pending.append(condition)
        else:
            self.predicates.setdefault(condition.code, (condition, condition.value))
        return condition.value

    def forced(self, expr: ParamExpr) -> float:
        """The value of a parameter expression as a Python number: every parameter it reads is then
        fixed at its value (a structural predicate each)."""
        if self.checking:
            self._opaque = True
        else:
            for i in sorted(expr.reads):
                self.predicates.setdefault(f"p[{i}] == {c_literal(self.values[i])}", (i, True))
        return expr.value

    # what the component's check() requires

    def _trace_checks(self) -> None:
        self.checking = True
        try:
            self.component.params_type.check(self.symbolic)
        except (TypeError, AttributeError, ValueError) as exc:
            self.python_checks.append(f"the whole of {self.component.params_type.__name__}.check ({exc})")
        finally:
            self.checking = False

    def required(self, name: str, condition, rule: str) -> None:
        """Parameters.require while check() runs: a range, a relation, or a rule only Python checks."""
        pending, opaque = self._pending, self._opaque
        self._pending, self._opaque = [], False
        index = self.names.index(name) if name in self.names else None
        if isinstance(condition, ParamCondition) and not opaque:
            if not pending:
                self.relations.append((name, condition))
                return
            if (index is not None and len(pending) == 1 and _bounds(pending[0], index, (">=",))
                    and _bounds(condition, index, ("<=",))):
                unit = _RANGE_RULE.match(rule)
                self.ranges[index] = (float(pending[0].right), float(condition.right), unit.group(1) if unit else "")
                return
        self.python_checks.append(f"{name} must {rule}")

    # the build's identity and checks

    def structure(self) -> list:
        """The structural predicates with their outcomes, sorted: what the build's C code depends on
        beyond the parameter array (JSON-able; with fixed values: every value)."""
        if self.fixed:
            return [[f"p[{i}] == {c_literal(v)}", True] for i, v in enumerate(self.values)]
        return sorted([code, bool(outcome)] for code, (_, outcome) in self.predicates.items())

    def structural_names(self) -> tuple:
        """The names of the parameters some structural predicate reads (with fixed values: all)."""
        if self.fixed:
            return self.names
        reads = set()
        for code, (what, _) in self.predicates.items():
            reads |= {what} if isinstance(what, int) else set(what.reads)
        return tuple(self.names[i] for i in sorted(reads))

    def rules(self) -> list[Rule]:
        """The checks the generated C makes, in order: ranges, structural predicates, relations
        (a trained space: each value fixed)."""
        model = self.component.name.upper()
        out = []
        for i, (low, high, unit) in sorted(self.ranges.items()):
            name = self.names[i]
            out.append(Rule("range", f"p[{i}] >= {c_literal(low)} && p[{i}] <= {c_literal(high)}",
                            f"parameter {name} = %.16g {unit} lies outside [{low:g}, {high:g}] {unit}, the range "
                            f"{model} accepts", (i,), frozenset({i})))
        if self.fixed:
            why = ("the operator was trained for {name} = {value!r} only (a surrogate FMU serves the one parameter "
                   "set it was trained for)" if self.fixed == "trained" else
                   "the FMU was built for {name} = {value!r} (the equations of " + model + " take every parameter "
                   "as given); rebuild it for another value")
            for i, (name, value) in enumerate(zip(self.names, self.values)):
                # a trained value to the tolerance a grid case's operator is checked to (its equations
                # hold the value itself); a baked one exactly
                same = (f"fabs(p[{i}] - {c_literal(value)}) <= {c_literal(TRAINED_TOLERANCE * max(1.0, abs(value)))}"
                        if self.fixed == "trained" else f"p[{i}] == {c_literal(value)}")
                out.append(Rule(self.fixed, same, f"parameter {name} = %.16g refused: "
                                + why.format(name=name, value=value), (i,), frozenset({i})))
            return out
        for code, (what, outcome) in sorted(self.predicates.items()):
            if isinstance(what, int):
                name = self.names[what]
                out.append(Rule("structural", code, f"structural parameter {name} = %.16g refused: the FMU was built "
                                f"for {name} = {self.values[what]!r}; rebuild it for another value", (what,),
                                frozenset({what})))
                continue
            held = what.text if outcome else what.negated_text()
            shown = tuple(sorted(what.reads))
            now = ", ".join(f"{self.names[i]} = %.16g" for i in shown)
            refused = (f"structural parameter {now} refused" if len(shown) == 1 else
                       f"structural parameters refused ({now})")
            out.append(Rule("structural", f"({code})" if outcome else f"!({code})",
                            f"{refused}: the FMU was built for {held}, which its equations take as given; rebuild it "
                            "for these values", shown, what.reads))
        for name, condition in self.relations:
            shown = tuple(sorted(condition.reads))
            now = ", ".join(f"{self.names[i]} = %.16g" for i in shown)
            out.append(Rule("relation", condition.code, f"parameter {name}: {condition.text} must hold ({now})",
                            shown, condition.reads))
        return out


def _bounds(condition: ParamCondition, index: int, ops: tuple) -> bool:
    """condition is `p[index] op number` with op in ops."""
    return (isinstance(condition.left, ParamExpr) and condition.left.code == f"p[{index}]" and condition.op in ops
            and not isinstance(condition.right, ParamExpr))


def _symbolic_params(params_type: type, space: ParameterSpace):
    """An instance of (a subclass of) params_type whose fields are the space's parameters, whose
    require() reports to the space."""

    def require(self, name, condition, rule):
        space.required(name, condition, rule)

    cls = type(f"Symbolic{params_type.__name__}", (params_type,), {"require": require, "__module__": __name__})
    obj = object.__new__(cls)
    for name, expr in zip(space.names, space.base):
        object.__setattr__(obj, name, expr)
    return obj


def _escape(text: str) -> str:
    """text inside a C string literal (the message formats' own %.16g kept)."""
    return (text.replace("\\", "\\\\").replace('"', '\\"').replace("%", "%%").replace("%%.16g", "%.16g")
            .replace("\n", " "))


def parameters_c_source(space: ParameterSpace, linkage: str = "static") -> str:
    """C source of
        model_derive(p)                       the derived parameters p[n..] from the parameters p[0..n)
        model_check_parameters(p, only, why, size)   MODEL_ERROR (why written) where a rule does not hold:
            with only >= 0, the rules that read parameter `only` alone (a value being set); with
            only < 0, every rule (at initialisation)
    for the space's parameters (needs model.h's ModelStatus, <stdio.h>, <math.h>)."""
    lines = [f"/* the derived parameters of {space.component.name} (p[{space.n}] on) from its parameters */",
             f"{linkage} void model_derive(double p[{space.size}])", "{", "    (void)p;"]
    lines += [f"    p[{space.n + k}] = {expression};" for k, (expression, _) in enumerate(space.derived)]
    lines += ["}", "",
              f"/* MODEL_ERROR (why written) unless the parameters p (derived ones computed) pass the rules that read "
              f"only parameter `only` (>= 0) or every rule (only < 0) */",
              f"{linkage} ModelStatus model_check_parameters(const double p[{space.size}], int only, char *why, "
              "size_t size)", "{", "    (void)p;", "    (void)only;", "    (void)why;", "    (void)size;"]
    for rule in space.rules():
        when = f"only == {next(iter(rule.reads))}" if len(rule.reads) == 1 else "0"
        values = "".join(f", p[{i}]" for i in rule.shown)
        lines += [f"    if ((only < 0 || {when}) && !({rule.code})) {{",
                  f'        snprintf(why, size, "{_escape(rule.message)}"{values});',
                  "        return MODEL_ERROR;", "    }"]
    lines += ["    return MODEL_OK;", "}", ""]
    return "\n".join(lines)
