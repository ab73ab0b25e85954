"""Import structure: no import cycles in identify/, simulate/, service/; the CLI's help and the model
registry load no torch.

The import graph is built with :mod:`ast` from every import statement of each module, the ones
inside functions included: a lazy import that closes a cycle still ties both modules together (each
needs the other to work), it only defers the failure. Type-only imports under ``if TYPE_CHECKING:``
are not edges. ``ast`` rather than a graph tool (grimp, pydeps): no dependency, and it reads the
``TYPE_CHECKING`` exemption exactly as written here.
"""
from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("identify", "simulate", "service")


def module_files(packages=PACKAGES) -> dict[str, Path]:
    """Module name -> file, for every module of ``packages`` under the repository root."""
    mods = {}
    for pkg in packages:
        for f in sorted((ROOT / pkg).rglob("*.py")):
            parts = list(f.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            mods[".".join(parts)] = f
    return mods


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _runtime_imports(body: list[ast.stmt]):
    """Every import statement of ``body`` and the blocks, functions and classes in it, except those
    under ``if TYPE_CHECKING:``."""
    for node in body:
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        elif isinstance(node, ast.If) and _is_type_checking(node.test):
            yield from _runtime_imports(node.orelse)
        else:
            for child in ast.iter_child_nodes(node):
                if isinstance(child, ast.stmt):
                    yield from _runtime_imports([child])
                elif isinstance(child, ast.excepthandler):
                    yield from _runtime_imports(child.body)


def import_graph(mods: dict[str, Path]) -> dict[str, set[str]]:
    """Edges module -> project modules it imports at import time."""
    graph: dict[str, set[str]] = {}
    for name, f in mods.items():
        is_pkg = f.name == "__init__.py"
        edges = set()
        for node in _runtime_imports(ast.parse(f.read_text(), str(f)).body):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                base = node.module or ""
                if node.level:
                    anchor = name.split(".") if is_pkg else name.split(".")[:-1]
                    anchor = anchor[: len(anchor) - (node.level - 1)]
                    base = ".".join(anchor + ([base] if base else []))
                # "from pkg import sub" imports the submodule pkg.sub when there is one
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in mods else base for a in node.names]
            for t in targets:
                while t and t not in mods:  # "import a.b.c" of a non-module attribute: its module
                    t = t.rpartition(".")[0]
                if t and t != name:
                    edges.add(t)
        graph[name] = edges
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10_000))

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_cycle_finder_finds_a_planted_cycle():
    g = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert cycles(g) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_graph_reads_runtime_imports_not_type_only(tmp_path, monkeypatch):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from typing import TYPE_CHECKING\nfrom . import b\nif TYPE_CHECKING:\n"
                              "    from pkg.c import C\n")
    (pkg / "b.py").write_text("try:\n    import os\nexcept ImportError:\n    pass\ndef f():\n    from pkg.a import x\n")
    (pkg / "c.py").write_text("import pkg.a\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    g = import_graph(module_files(("pkg",)))
    assert g["pkg.a"] == {"pkg.b"} and g["pkg.b"] == {"pkg.a"} and g["pkg.c"] == {"pkg.a"}
    assert cycles(g) == [["pkg.a", "pkg.b"]]


@pytest.mark.parametrize("package", PACKAGES)
def test_no_import_cycles(package):
    graph = import_graph(module_files())
    found = [c for c in cycles(graph) if any(m.split(".")[0] == package for m in c)]
    assert found == [], f"import cycles in {package}/: " + "; ".join(" <-> ".join(c) for c in found)


_LOADED = """
import json, sys
{code}
print(json.dumps(sorted(m for m in sys.modules if m.split(".")[0] in ("torch", "lightning"))))
"""


def _heavy_modules(code: str) -> list[str]:
    """torch/lightning modules in ``sys.modules`` after running ``code`` in a fresh interpreter."""
    res = subprocess.run([sys.executable, "-c", _LOADED.format(code=code)], capture_output=True, text=True,
                         cwd=ROOT, timeout=120)
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout.strip().splitlines()[-1])


def _cli(*args: str) -> str:
    return (f"sys.argv = ['greybench', {', '.join(repr(a) for a in args)}]\n"
            "try:\n    main()\nexcept SystemExit as e:\n    assert e.code in (0, None), e.code\n")


def test_no_torch_until_a_learned_model_is_used():
    """The model registry, a LuGre model, ``greybench --help``, a command's and the benchmarks' help:
    in one interpreter (one start-up), so no step loads torch; the benchmark package loads only for
    ``greybench bench``."""
    code = ("import identify.models\nfrom identify.models import MODELS, LuGre, make_model\n"
            "list(MODELS); make_model('lugre')\nfrom greybench.cli import main\n"
            + _cli("--help") + _cli("fit", "--help")
            + "assert 'greybench_bench' not in sys.modules, 'benchmarks loaded without greybench bench'\n"
            + _cli("bench", "--help") + "assert 'greybench_bench.friction' in sys.modules\n")
    assert _heavy_modules(code) == []


def test_a_learned_model_loads_torch():
    """The check above sees torch when it is loaded: asking for a learned model class imports it."""
    assert "torch" in _heavy_modules("from identify.models import MODELS; MODELS['lstm']")



_COMMAND_LOADS = """
import json, runpy, sys
for args in {calls!r}:
    sys.argv = ['greybench'] + args
    try:
        runpy.run_module('greybench.cli', run_name='__main__')
    except SystemExit as e:
        assert e.code in {codes!r}, (args, e.code)
print(json.dumps(sorted(m for m in {heavy!r} if m in sys.modules)))
"""
HEAVY = ("numba", "scipy", "torch", "mlflow")


def _command_loads(*calls: list[str], codes: tuple = (0, None), cwd: Path = ROOT) -> list[str]:
    """Which of numba, scipy, torch, mlflow console runs of ``greybench <call>`` imported, one after
    the other in one fresh interpreter (a module any of them loads stays in ``sys.modules``); each must
    exit with one of ``codes``."""
    code = _COMMAND_LOADS.format(calls=list(calls), heavy=HEAVY, codes=codes)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, (str(ROOT), os.environ.get("PYTHONPATH"))))}
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=cwd, env=env, timeout=120)
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_light_commands_import_no_numba_scipy_torch_or_mlflow(tmp_path):
    """Seconds of start-up per call: a command imports only what it uses, so generating a trajectory, printing
    the MLflow UI command, and the help of the commands that run simulations or the diagnosis, load none of the
    friction models, plant, simulation or tracking store."""
    out = tmp_path / "ut.csv"
    helps = [[cmd, "--help"] for cmd in ("trajectory", "rank-poses", "trace", "circle", "machine", "compensate",
                                         "serve", "diagnose", "ui")]
    run = ["trajectory", "universal", "--axis", "1", "--duration", "1", "--out", str(out)]
    assert _command_loads(run, ["ui", "--print-only"], *helps) == []
    assert out.stat().st_size > 0


def test_friction_commands_load_numba_scipy_and_mlflow_but_no_torch(tmp_path, monkeypatch):
    """The check above sees numba, scipy and mlflow when loaded: the friction commands' options name the models
    and the plant, and promoting a fit opens the tracking store (here an empty one in ``tmp_path``: an unknown
    name, exit 2), but no learned model (torch)."""
    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    loaded = set(_command_loads(["synth", "--help"], ["promote", "--name", "no-such-model"], codes=(0, 2),
                                cwd=tmp_path))
    assert {"numba", "scipy", "mlflow"} <= loaded and "torch" not in loaded


def test_ui_print_only_names_the_store_of_the_working_folder(tmp_path, monkeypatch):
    """The light path prints the tracking module's command line: this interpreter running ``mlflow ui`` on
    ``<cwd>/mlruns.db`` with its artifacts beside it."""
    import shlex

    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    code = ("import sys; sys.argv = ['greybench', 'ui', '--print-only', '--port', '5123']\n"
            "from greybench.cli import main\nmain()\n")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, env=env,
                         timeout=120)
    assert res.returncode == 0, res.stderr
    root = tmp_path.resolve()
    assert shlex.split(res.stdout.strip()) == [sys.executable, "-m", "mlflow", "ui", "--backend-store-uri",
                                               f"sqlite:///{root / 'mlruns.db'}", "--host", "127.0.0.1", "--port",
                                               "5123", "--default-artifact-root", (root / "mlartifacts").as_uri()]
    assert not (root / "mlruns.db").exists()  # printing creates no store
