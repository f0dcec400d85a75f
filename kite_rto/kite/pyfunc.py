"""Translate a scalar-graph CasADi ``SX`` function into a plain Python function.

Calling a :class:`casadi.Function` from Python costs 150-400 µs per call on the target machine (measured
with ``benchmarks/run.py``), far more than evaluating the kite's few dozen operations. The simulation
therefore runs a pure-Python translation of the *same* CasADi expression graph: the model is still written
once, symbolically; this module only changes how it is evaluated numerically.
"""
from __future__ import annotations

import casadi as ca

__all__ = ["to_python"]

_BINARY = {
    ca.OP_ADD: "{0} + {1}", ca.OP_SUB: "{0} - {1}", ca.OP_MUL: "{0} * {1}", ca.OP_DIV: "{0} / {1}",
    ca.OP_POW: "{0} ** {1}", ca.OP_CONSTPOW: "{0} ** {1}",
    # max(a, b) and min(a, b) exactly (NaN and signed zeros alike: b replaces a only if b > a, resp. b < a),
    # without the builtin's call: 20 ns instead of 90 (the model's wind has one per evaluation)
    ca.OP_FMAX: "({1} if {1} > {0} else {0})", ca.OP_FMIN: "({1} if {1} < {0} else {0})",
    ca.OP_ATAN2: "atan2({0}, {1})", ca.OP_COPYSIGN: "copysign({0}, {1})",
    ca.OP_LT: "float({0} < {1})", ca.OP_LE: "float({0} <= {1})", ca.OP_EQ: "float({0} == {1})",
    ca.OP_NE: "float({0} != {1})", ca.OP_AND: "float(bool({0}) and bool({1}))",
    ca.OP_OR: "float(bool({0}) or bool({1}))", ca.OP_HYPOT: "hypot({0}, {1})",
}
_UNARY = {
    ca.OP_ASSIGN: "{0}", ca.OP_NEG: "-{0}", ca.OP_SQ: "{0} * {0}", ca.OP_TWICE: "2.0 * {0}",
    ca.OP_INV: "1.0 / {0}", ca.OP_SQRT: "sqrt({0})", ca.OP_SIN: "sin({0})", ca.OP_COS: "cos({0})",
    ca.OP_TAN: "tan({0})", ca.OP_EXP: "exp({0})", ca.OP_LOG: "log({0})", ca.OP_FABS: "fabs({0})",
    ca.OP_ASIN: "asin({0})", ca.OP_ACOS: "acos({0})", ca.OP_ATAN: "atan({0})", ca.OP_TANH: "tanh({0})",
    ca.OP_SINH: "sinh({0})", ca.OP_COSH: "cosh({0})", ca.OP_NOT: "float(not {0})",
    ca.OP_FLOOR: "floor({0})", ca.OP_CEIL: "ceil({0})", ca.OP_SIGN: "copysign(1.0, {0}) if {0} else 0.0",
}
_MATH = ("sin", "cos", "tan", "sqrt", "exp", "log", "fabs", "asin", "acos", "atan", "atan2", "tanh", "sinh",
         "cosh", "floor", "ceil", "copysign", "hypot")
_BIND = ", ".join(f"{n}=_m.{n}" for n in _MATH)  # math functions as locals: faster than globals
_OP_NAMES = {getattr(ca, k): k for k in dir(ca) if k.startswith("OP_")}


def to_python(f: ca.Function):
    """Return a Python callable equivalent to the SX function ``f``.

    The callable takes one flat sequence of floats per input of ``f`` (scalars as plain floats) and returns
    a tuple with one list of floats per output (dense, column-major like CasADi).
    """
    if not f.is_a("SXFunction"):
        raise TypeError(f"to_python needs an SX function, got {f.class_name()} for {f.name()!r}")
    scalar_in = [f.numel_in(i) == 1 for i in range(f.n_in())]
    args = [f"a{i}" for i in range(f.n_in())]
    lines = [f"def {f.name()}({', '.join(args)}, {_BIND}):"]
    outs = [[None] * f.numel_out(i) for i in range(f.n_out())]
    for k in range(f.n_instructions()):
        op = f.instruction_id(k)
        inp, out = f.instruction_input(k), f.instruction_output(k)
        if op == ca.OP_INPUT:
            src = f"a{inp[0]}" if scalar_in[inp[0]] else f"a{inp[0]}[{inp[1]}]"
            lines.append(f"    w{out[0]} = {src}")
        elif op == ca.OP_OUTPUT:
            outs[out[0]][out[1]] = f"o{out[0]}_{out[1]}"
            lines.append(f"    o{out[0]}_{out[1]} = w{inp[0]}")
        elif op == ca.OP_CONST:
            lines.append(f"    w{out[0]} = {float(f.instruction_constant(k))!r}")
        elif op in _BINARY:
            lines.append(f"    w{out[0]} = " + _BINARY[op].format(f"w{inp[0]}", f"w{inp[1]}"))
        elif op in _UNARY:
            lines.append(f"    w{out[0]} = " + _UNARY[op].format(f"w{inp[0]}"))
        else:
            raise NotImplementedError(f"to_python: CasADi operation {_OP_NAMES.get(op, op)} in {f.name()!r}")
    for o in outs:  # outputs never assigned are structural zeros
        o[:] = ["0.0" if v is None else v for v in o]
    lines.append("    return (" + "".join(f"[{', '.join(o)}], " for o in outs) + ")")
    namespace: dict = {}
    exec("import math as _m\n" + "\n".join(lines), namespace)  # noqa: S102 - source generated above
    fn = namespace[f.name()]
    fn.__doc__ = f"Pure-Python translation of CasADi function {f.name()!r}."
    return fn
