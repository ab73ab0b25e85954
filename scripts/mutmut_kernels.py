"""mutmut with the numba kernels of chosen modules mutated too (``make mutation`` runs this).

mutmut 3 skips every function with a decorator other than ``staticmethod``/``classmethod``, so the
``@njit`` kernels, where most of the arithmetic of the drive, loop-friction and switching-point
modules lives, would never be mutated. For the modules listed in ``python_kernels`` of
``[tool.greybench.mutation]`` (pyproject.toml) this wrapper removes the ``@njit(...)`` decorator
lines from the copy mutmut mutates (``mutants/``; the sources are untouched): the kernels become
plain Python functions there, mutmut mutates them like any other function and the tests, which
call the kernels directly or through the module's Python entry points, run the mutants as Python.
The default test run (``make test``) runs the same tests on the compiled kernels.

A module in that list must not have its kernels called from a compiled function of another module
by the tests mutmut runs (numba cannot call a plain Python function): the tests in ``tests/mutation``
call them directly. Usage: the arguments of ``mutmut`` (``python scripts/mutmut_kernels.py run ...``).
"""
from __future__ import annotations

import re
import sys
import tomllib
from pathlib import Path

import mutmut.__main__ as mutmut_main

# a decorator line of numba's njit, with or without arguments; replaced by an empty line (same line numbers)
NJIT_LINE = re.compile(r"^[ \t]*@njit(?:\(.*\))?[ \t]*$", re.MULTILINE)


def python_kernels(pyproject: Path = Path("pyproject.toml")) -> set[str]:
    """The source paths whose njit kernels are mutated as Python (``[tool.greybench.mutation]``)."""
    doc = tomllib.loads(pyproject.read_text("utf-8"))
    return set(doc.get("tool", {}).get("greybench", {}).get("mutation", {}).get("python_kernels", []))


def strip_njit(source: str) -> str:
    """``source`` without its ``@njit`` decorator lines (each replaced by an empty line)."""
    return NJIT_LINE.sub("", source)


def main() -> None:
    kernels = python_kernels()
    write = mutmut_main.write_all_mutants_to_file

    def write_stripped(*, out, source, filename):
        # mutants are generated in a pool forked from this process, so the replacement applies there too
        if Path(filename).as_posix() in kernels:
            source = strip_njit(source)
        return write(out=out, source=source, filename=filename)

    mutmut_main.write_all_mutants_to_file = write_stripped
    sys.argv[0] = "mutmut"
    mutmut_main.cli()


if __name__ == "__main__":
    main()
