"""A conditional for equations written against a math namespace (component.py): `where`.

A component's equations run on the `math` module (scalars), numpy, torch and the C tracers of
fmu_export (`CMath`, `DualMath`). numpy, torch and the tracers have `where(condition, a, b)`; the
`math` module has none, so a component calls `where(m, condition, a, b)` from here, which takes
Python's conditional expression there. Conditions are comparisons (<, <=, >, >=) of the namespace's
values with each other or with numbers; nest `where` to combine them. Both branches are evaluated
(numpy, torch, the tracers), so each must be finite wherever the other is taken.
"""
from __future__ import annotations


def where(m, condition, a, b):
    """a where `condition` holds, else b, in the math namespace m."""
    select = getattr(m, "where", None)
    if select is None:  # the math module: scalars
        return a if condition else b
    return select(condition, a, b)
