"""One equation source, two compilers: numba (CPU engine) and Warp (batch engine).

The control law is written once as small scalar Python functions (see
``bioform_mj.core.equations``, registry ``EQUATIONS``). :func:`warp_equations` turns such a module
into ``wp.func`` objects *from the same source text*; :func:`numba_equations` does the
same for numba (used by the tests as the CPU reference). What the Warp translation does,
and nothing more:

* reads each function's source (``inspect.getsource``; the ``.py_func`` of a numba
  dispatcher), drops its decorators and annotations;
* types every number literal in the chosen precision (``2.0`` → ``_F(2.0)``);
* rewrites ``a % b`` into ``_pymod(a, b)``, Python's *floored* modulo: Warp's ``%`` on
  floats is C ``fmod`` (sign of the dividend), so ``wrap(a) = π − (π − a) % 2π`` would
  return ``a`` unchanged for every ``a > π``;
* compiles the result under a ``<bioform_mj.batch:…>`` file name registered in
  ``linecache`` (Warp's code generator reads function source through ``linecache``,
  so no temporary file is needed) and executes it in a namespace where the module's
  ``math`` functions are Warp's (``cos`` → ``wp.cos`` …, matched by identity, so
  ``from math import cos`` and ``cos = math.cos`` both work), its float constants are
  typed constants of the chosen precision, and every other equation of the module is
  its Warp translation (so equations may call each other);
* annotates every parameter with the chosen float type (``wp.float32`` by default;
  a parameter annotated ``bool``/``int`` in the source keeps that type) and registers
  the function with ``wp.func`` in one Warp module per (source module, precision).

Everything else (tuple returns, ``if``/early ``return``, ``min``/``max``/``abs``,
``and``/``or``) is Warp's own Python subset, unchanged.
"""

from __future__ import annotations

import ast
import inspect
import linecache
import math
import textwrap
import types
from collections.abc import Iterable

__all__ = ["equation_functions", "warp_equations", "numba_equations", "warp_map"]


def _plain(obj):
    """The Python function behind ``obj`` (itself, or a numba dispatcher's ``py_func``)."""
    return getattr(obj, "py_func", obj)


def equation_functions(module: types.ModuleType, names: Iterable[str] | None = None) -> dict[str, types.FunctionType]:
    """The equations of ``module``, by name: its registry ``EQUATIONS`` (name → plain function,
    as in ``bioform_mj.core.equations``) if it has one, else its functions defined in it
    (not imported, not ``_private``)."""
    out = {}
    registry = getattr(module, "EQUATIONS", None)
    if isinstance(registry, dict):
        out = {name: _plain(f) for name, f in registry.items()}
    else:
        for name, obj in vars(module).items():
            f = _plain(obj)
            if isinstance(f, types.FunctionType) and f.__module__ == module.__name__ and not name.startswith("_"):
                out[name] = f
    if names is not None:
        names = list(names)
        missing = [n for n in names if n not in out]
        if missing:
            raise KeyError(f"{module.__name__} has no equation(s) {missing}")
        out = {n: out[n] for n in names}
    return out


# ----------------------------------------------------------------------------- Warp
class _Rewrite(ast.NodeTransformer):
    """``a % b`` → ``_pymod(a, b)``; ``a %= b`` → ``a = _pymod(a, b)``; a number literal
    ``2.0`` (or ``2``) → ``_F(2.0)``, typed in the chosen precision (Warp types a bare
    literal as float32, and refuses ``float64 * float32`` or ``float * int``)."""

    def visit_Constant(self, node):
        if isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
            return ast.copy_location(ast.Call(ast.Name("_F", ast.Load()), [ast.Constant(float(node.value))], []), node)
        return node

    def visit_BinOp(self, node):
        self.generic_visit(node)
        if isinstance(node.op, ast.Mod):
            return ast.copy_location(ast.Call(ast.Name("_pymod", ast.Load()), [node.left, node.right], []), node)
        return node

    def visit_AugAssign(self, node):
        self.generic_visit(node)
        if isinstance(node.op, ast.Mod) and isinstance(node.target, ast.Name):
            call = ast.Call(ast.Name("_pymod", ast.Load()), [ast.Name(node.target.id, ast.Load()), node.value], [])
            return ast.copy_location(ast.Assign([ast.Name(node.target.id, ast.Store())], call), node)
        return node


def _strip(fn: types.FunctionType) -> str:
    """Source of ``fn`` without decorators or annotations, ``%`` rewritten."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(fn)))
    fdef = tree.body[0]
    if not isinstance(fdef, ast.FunctionDef):
        raise TypeError(f"{fn.__qualname__}: expected a plain 'def'")
    fdef.decorator_list = []
    fdef.returns = None
    for a in fdef.args.args:
        a.annotation = None
    fdef = _Rewrite().visit(fdef)
    return ast.unparse(ast.fix_missing_locations(ast.Module([fdef], type_ignores=[]))) + "\n"


def _compile_in(source: str, filename: str, ns: dict, name: str) -> types.FunctionType:
    lines = source.splitlines(keepends=True)
    linecache.cache[filename] = (len(source), None, lines, filename)
    exec(compile(source, filename, "exec"), ns)  # noqa: S102 - our own equations, rewritten
    return ns[name]


def _math_table(wp) -> dict:
    """``math`` function (by identity) → Warp builtin."""
    pairs = {
        "cos": wp.cos,
        "sin": wp.sin,
        "tan": wp.tan,
        "exp": wp.exp,
        "log": wp.log,
        "atan2": wp.atan2,
        "atan": wp.atan,
        "asin": wp.asin,
        "acos": wp.acos,
        "sqrt": wp.sqrt,
        "floor": wp.floor,
        "ceil": wp.ceil,
        "fabs": wp.abs,
        "tanh": wp.tanh,
        "cosh": wp.cosh,
        "sinh": wp.sinh,
        "trunc": wp.trunc,
        "isfinite": wp.isfinite,
        "isnan": wp.isnan,
        "isinf": wp.isinf,
    }
    return {getattr(math, k): v for k, v in pairs.items()}


_CACHE: dict = {}


def warp_equations(module: types.ModuleType, dtype=None, names: Iterable[str] | None = None) -> types.SimpleNamespace:
    """Warp versions (``wp.func``) of the equations of ``module``, from its source.

    ``dtype``: the float type of every parameter and constant (default ``wp.float32``;
    ``wp.float64`` works on CPU and GPU). Returns a namespace ``eq`` whose attributes are
    callable from Warp kernels as ``eq.name(...)`` (or bind them to module globals).
    Translations are cached per (module, dtype).
    """
    import warp as wp

    dtype = wp.float32 if dtype is None else dtype
    key = (module.__name__, dtype.__name__)
    if key in _CACHE and names is None:
        return _CACHE[key]
    funcs = equation_functions(module)
    wmod = f"bioform_eq_{module.__name__.replace('.', '_')}_{dtype.__name__}"
    table = _math_table(wp)
    ns: dict = {"__name__": wmod, "__builtins__": __builtins__}
    shim = types.SimpleNamespace(pi=dtype(math.pi), e=dtype(math.e), tau=dtype(2 * math.pi))
    for fobj, wfun in table.items():
        setattr(shim, fobj.__name__, wfun)
    for name, val in vars(module).items():
        if name.startswith("__"):
            continue
        if val is math:
            ns[name] = shim
        elif isinstance(val, types.BuiltinFunctionType) and val in table:
            ns[name] = table[val]
        elif val is math.hypot:  # no Warp builtin: sqrt(a² + b²) (no overflow guard; our inputs are O(1))
            ns[name] = _hypot_func(wp, dtype, wmod)
        elif isinstance(val, bool):
            ns[name] = wp.constant(val)
        elif isinstance(val, float):
            ns[name] = wp.constant(dtype(val))
        elif isinstance(val, int):
            ns[name] = wp.constant(val)
    ns["_pymod"] = _pymod_func(wp, dtype, wmod)
    ns["_F"] = dtype
    types_map = {float: dtype, int: wp.int32, bool: wp.bool, "float": dtype, "int": wp.int32, "bool": wp.bool}
    out = {}
    for name, fn in funcs.items():  # all first (bodies resolve names at kernel build time)
        src = _strip(fn)
        g = _compile_in(src, f"<bioform_mj.batch:{module.__name__}.{name}:{dtype.__name__}>", ns, name)
        code = fn.__code__
        orig = getattr(fn, "__annotations__", {})
        g.__annotations__ = {a: types_map.get(orig.get(a), dtype) for a in code.co_varnames[: code.co_argcount]}
        g.__module__ = wmod
        g.__qualname__ = name
        wf = wp.func(g, module=wmod)
        ns[name] = wf
        out[name] = wf
    result = types.SimpleNamespace(**out)
    if names is not None:
        result = types.SimpleNamespace(**{n: out[n] for n in names})
    else:
        _CACHE[key] = result
    return result


def _hypot_func(wp, dtype, wmod):
    """``math.hypot(a, b)`` as a Warp function: ``sqrt(a² + b²)``."""
    src = "def _hypot(a, b):\n    return wp.sqrt(a * a + b * b)\n"
    ns = {"wp": wp, "__name__": wmod}
    f = _compile_in(src, f"<bioform_mj.batch:_hypot:{dtype.__name__}>", ns, "_hypot")
    f.__annotations__ = {"a": dtype, "b": dtype}
    f.__module__ = wmod
    return wp.func(f, module=wmod)


def _pymod_func(wp, dtype, wmod):
    """Python's floored float modulo (CPython ``float_rem``) as a Warp function."""
    src = (
        "def _pymod(a, b):\n"
        "    r = wp.mod(a, b)\n"
        "    if r != zero and ((r < zero) != (b < zero)):\n"
        "        r = r + b\n"
        "    return r\n"
    )
    ns = {"wp": wp, "zero": wp.constant(dtype(0.0)), "__name__": wmod}
    f = _compile_in(src, f"<bioform_mj.batch:_pymod:{dtype.__name__}>", ns, "_pymod")
    f.__annotations__ = {"a": dtype, "b": dtype}
    f.__module__ = wmod
    return wp.func(f, module=wmod)


# ----------------------------------------------------------------------------- numba
def numba_equations(module: types.ModuleType) -> types.SimpleNamespace:
    """numba ``njit`` versions of the equations of ``module`` (calls between equations
    resolve to the compiled versions). The CPU reference for the tests."""
    import numba

    funcs = equation_functions(module)
    ns = dict(vars(module))
    out = {}
    for name, fn in funcs.items():
        g = types.FunctionType(fn.__code__, ns, name, fn.__defaults__, fn.__closure__)
        jf = numba.njit(error_model="numpy")(g)
        ns[name] = jf
        out[name] = jf
    return types.SimpleNamespace(**out)


# ----------------------------------------------------------------------------- helper
_MAP_KERNELS: dict = {}


def warp_map(wfunc, nargs: int, nout: int, dtype=None, device: str | None = None, bool_args=()):
    """A callable ``f(*arrays) -> ndarray (N, nout)`` that evaluates the Warp function
    ``wfunc`` (``nargs`` scalar inputs, ``nout`` scalar outputs) elementwise on the device.
    Used to check a translation against its numba twin. ``bool_args``: indices of the
    arguments that are ``bool`` in the source (passed as ``a != 0``)."""
    import numpy as np
    import warp as wp

    dtype = wp.float32 if dtype is None else dtype
    bool_args = tuple(bool_args)
    k = (id(wfunc), nargs, nout, dtype.__name__, bool_args)
    if k not in _MAP_KERNELS:
        args = ", ".join(f"a{i}: wp.array(dtype=F)" for i in range(nargs))
        call = ", ".join(f"a{i}[i] != F(0.0)" if i in bool_args else f"a{i}[i]" for i in range(nargs))
        outs = ", ".join(f"r{j}" for j in range(nout))
        body = "".join(f"    out[i, {j}] = F(r{j})\n" for j in range(nout))
        name = f"_map_{abs(hash(k))}"
        src = f"def {name}({args}, out: wp.array2d(dtype=F)):\n    i = wp.tid()\n    {outs} = fn({call})\n{body}"
        ns = {"wp": wp, "F": dtype, "fn": wfunc, "__name__": f"bioform_map_{name}"}
        kf = _compile_in(src, f"<bioform_mj.batch:{name}>", ns, name)
        kf.__module__ = ns["__name__"]
        _MAP_KERNELS[k] = wp.kernel(kf, module="unique")
    kernel = _MAP_KERNELS[k]

    def run(*arrays):
        n = len(arrays[0])
        dev = device or "cpu"
        ins = [wp.array(np.asarray(a, dtype=wp.dtype_to_numpy(dtype)), dtype=dtype, device=dev) for a in arrays]
        out = wp.zeros((n, nout), dtype=dtype, device=dev)
        wp.launch(kernel, dim=n, inputs=[*ins, out], device=dev)
        return out.numpy()

    return run
