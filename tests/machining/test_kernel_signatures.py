"""Compiled kernels take named structures: no numba-jitted function in simulate/ has more than 14 parameters.

A kernel with dozens of positional arrays is easy to call with two of them swapped (same dtype and
shape, no error, wrong numbers); named tuples (a ray family, the grid, the cutter, the buffers) make
such a swap a field name. The walk reads the source with ``ast``, so it sees every decorated
function without compiling anything.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

SIMULATE = Path(__file__).resolve().parents[2] / "simulate"
MAX_PARAMETERS = 14
#: Decorators that compile a function with numba (bare or called, plain or as ``numba.<name>``).
_JIT_NAMES = {"njit", "jit", "generated_jit", "vectorize", "guvectorize", "cfunc", "stencil"}


def _decorator_name(node: ast.expr) -> str:
    if isinstance(node, ast.Call):
        node = node.func
    if isinstance(node, ast.Attribute):
        return node.attr
    if isinstance(node, ast.Name):
        return node.id
    return ""


def parameter_count(fn: ast.FunctionDef) -> int:
    a = fn.args
    return (len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + (a.vararg is not None)
            + (a.kwarg is not None))


def jitted_functions(source: str) -> list[tuple[str, int, int]]:
    """``(name, line, parameters)`` of every numba-decorated function in ``source``."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and any(
                _decorator_name(d) in _JIT_NAMES for d in node.decorator_list):
            out.append((node.name, node.lineno, parameter_count(node)))
    return out


def test_the_walk_finds_kernels_and_counts_parameters():
    # the checker itself against known source: decorated forms counted, undecorated ones ignored
    src = (
        "import numba\nfrom numba import njit, prange\n"
        "@njit(cache=True)\ndef a(x, y, *, z=1): pass\n"
        "@numba.njit\ndef b(*args, **kw): pass\n"
        "@njit(parallel=True, cache=True)\ndef c(" + ", ".join(f"p{i}" for i in range(15)) + "): pass\n"
        "def d(" + ", ".join(f"p{i}" for i in range(30)) + "): pass\n"
    )
    assert jitted_functions(src) == [("a", 4, 3), ("b", 6, 2), ("c", 8, 15)]


def test_the_walk_sees_the_machining_kernels():
    names = {name for p in SIMULATE.rglob("*.py") for name, _, _ in jitted_functions(p.read_text())}
    # the kernels of the coupled loop, the removal and the forces are among what is checked
    assert {"coupled_steps", "cut_layer", "remove_vertical", "step_forces_sorted", "drive_step"} <= names


@pytest.mark.parametrize("path", sorted(SIMULATE.rglob("*.py")), ids=lambda p: str(p.relative_to(SIMULATE)))
def test_kernels_have_at_most_14_parameters(path):
    too_many = [f"{path.name}:{line} {name} has {n} parameters"
                for name, line, n in jitted_functions(path.read_text()) if n > MAX_PARAMETERS]
    assert not too_many, "; ".join(too_many) + f" (at most {MAX_PARAMETERS}: group them in named tuples)"
