"""Compile and cache the simulation kernels before the first real simulation (``python -m simulate.warmup``).

numba compiles a kernel on its first call for the argument types of that call and caches it on disk
next to the sources (``cache=True``). A fresh clone therefore spends about a minute of one core
compiling the coupled machining loop, the drives, the friction models and the kinematics in its first
simulation -- and ``rank-poses`` with two worker processes compiles them in both. ``make demo``
(``scripts/demo.sh``) runs this warm-up in the background while it identifies the friction model
(which needs none of these kernels), so the simulations after it load the kernels from the cache.

The warm-up runs the one machining pipeline (:func:`simulate.pipeline.run_job`) on two tiny cases with
the argument types of the real runs, and throws their results away:

- a short cut (arc in, line, arc) of the square contour of the ISO 10791-7 160 mm test piece at its
  first pose, with the ranking's stock trimming and dexel spacing, deflection, drives with friction
  and gear play, switching bits (the types ``rank-poses`` and ``compensate`` call the loop with;
  every friction model kind travels in the same :data:`~simulate.robot.loop_friction.LoopFriction`
  arrays, so the robot file's models stand for a fitted one);
- a 5 mm ballbar circle without stock (``greybench circle``'s types: no stock, no compliance).

What it compiled and what it found cached is counted from numba's dispatchers
(:class:`WarmupResult`). If the later runs' argument types drift from these, the later runs compile
again (slower, not wrong); ``tests/machining/test_warmup.py`` checks that the circle and a short
stock cut add no kernel signature after the warm-up.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path

from identify.errors import InputError
from identify.progress import Progress, plain, quiet
from simulate import defaults

DATA_DIR = Path(__file__).resolve().parents[1] / "data"
#: The robot, poses and stock the demo machines (``make demo``).
ROBOT = DATA_DIR / "robots" / "max100.toml"
POSES = DATA_DIR / "poses" / "iso160.json"
STOCK = DATA_DIR / "programs" / "iso160.stock.json"

#: A few centimetres of the 160 piece's square contour (mm, workpiece frame, as ``data/programs/iso160.nc``):
#: feed arc into the contour, a line along it, an arc out; about 2 s of machining at 2 ms steps.
CUT_PROGRAM = """%
(greybench kernel warm-up: a short cut of the 160 mm test piece's square contour)
G21 G90 G17 G94
T1 M6
S12000 M3
G0 X-65 Y70 Z29
G0 X-65 Y70 Z2
G1 X-65 Y70 Z0 F500
G3 X-55 Y60 I10 J0 F2000
G1 X-45 Y60 Z0
G2 X-40 Y55 I0 J-5
G0 X-40 Y55 Z29
M30
%
"""
#: Radius [m] and feed [m/s] of the warm-up's ballbar circle (about 1 s of motion).
CIRCLE_RADIUS = 5e-3
CIRCLE_FEED = 2000.0 / 6e4


@dataclass(frozen=True)
class WarmupResult:
    """What a warm-up ran and what numba did.

    Attributes
    ----------
    cut_steps : int
        2 ms steps of the short cut.
    removed : float
        m^3, material the short cut removed (> 0: the cutting paths ran).
    circle_steps : int
        2 ms steps of the circle.
    compiled : int
        Kernel signatures compiled by this process (0 when everything was cached).
    loaded : int
        Kernel signatures loaded from numba's on-disk cache.
    wall : float
        s, wall time of the warm-up.
    """

    cut_steps: int
    removed: float
    circle_steps: int
    compiled: int
    loaded: int
    wall: float


def _dispatchers():
    """The numba dispatchers of the loaded ``simulate`` modules, by qualified name."""
    from numba.core.registry import CPUDispatcher

    out = {}
    for name, mod in list(sys.modules.items()):
        if not name.startswith("simulate.") or mod is None:
            continue
        for obj in list(vars(mod).values()):
            if isinstance(obj, CPUDispatcher) and getattr(obj.py_func, "__module__", None) == name:
                out[f"{name}.{obj.py_func.__name__}"] = obj
    return out


def kernel_signatures() -> dict[str, int]:
    """Per simulation kernel (qualified name) the number of argument-type signatures this process has
    compiled or loaded; kernels not called yet are left out."""
    return {k: len(d.signatures) for k, d in sorted(_dispatchers().items()) if d.signatures}


def _kernel_counts() -> tuple[int, int]:
    """(compiled, loaded from the cache) signatures of this process's simulation kernels."""
    ds = _dispatchers().values()
    return (sum(sum(d.stats.cache_misses.values()) for d in ds), sum(sum(d.stats.cache_hits.values()) for d in ds))


def warm_up(robot: str | Path = ROBOT, poses: str | Path = POSES, stock: str | Path = STOCK, *,
            progress: Progress = quiet) -> WarmupResult:
    """Run the two tiny cases (module docstring) so their kernels are compiled and cached.

    ``robot``: robot TOML; ``poses``: pose file (the first pose is used); ``stock``: the 160 mm test
    piece's stock description. ``InputError`` names a missing or bad file.
    """
    from simulate.evaluation.circle import CircleSpec, simulate_circle
    from simulate.evaluation.ranking import RankSettings
    from simulate.pipeline import MachiningJob, load_program, run_job
    from simulate.robot.model import load_robot
    from simulate.toolpath.placement import load_poses

    t0 = time.perf_counter()
    rob = load_robot(robot)
    pose = load_poses(poses)[0]
    stock = Path(stock)
    try:
        stock_text = stock.read_text(encoding="utf-8")
    except OSError:
        raise InputError("stock description not found", source=str(stock)) from None
    # the ranking's settings without the virtual CMM (numpy and scipy, nothing to compile)
    settings = replace(RankSettings(size=160).machining(), size=0, features=False)
    with tempfile.TemporaryDirectory(prefix="greybench-warmup-") as tmp:
        prog = Path(tmp) / "warmup.nc"
        prog.write_text(CUT_PROGRAM, encoding="utf-8")
        (Path(tmp) / "warmup.stock.json").write_text(stock_text, encoding="utf-8")
        setup = load_program(prog, require_spindle=True)
        with progress("warm-up: compiling the machining loop (short cut)", None) as advance:
            cut = run_job(MachiningJob(program=setup, robot=rob, placement=pose, settings=settings), advance=advance)
    with progress("warm-up: compiling the circle's kernels (5 mm circle)", None) as advance:
        circle = simulate_circle(rob, pose, CircleSpec(radius=CIRCLE_RADIUS, feed=CIRCLE_FEED), advance=advance)
    compiled, loaded = _kernel_counts()
    return WarmupResult(cut_steps=len(cut.trajectory.t), removed=cut.result.removed_volume,
                        circle_steps=len(circle.t), compiled=compiled, loaded=loaded,
                        wall=time.perf_counter() - t0)


def main(argv: list[str] | None = None) -> int:
    """``python -m simulate.warmup [--robot R] [--poses P] [--stock S]``: warm up, print one JSON line
    (the :class:`WarmupResult`, SI), progress lines on stderr; exit 2 on bad input."""
    ap = argparse.ArgumentParser(prog="python -m simulate.warmup", description=__doc__.splitlines()[0])
    ap.add_argument("--robot", default=str(ROBOT), help="Robot TOML.")
    ap.add_argument("--poses", default=str(POSES), help="Pose file (JSON, m, rad); the first pose is used.")
    ap.add_argument("--stock", default=str(STOCK), help="Stock description of the 160 mm test piece (JSON).")
    args = ap.parse_args(argv)
    try:
        res = warm_up(args.robot, args.poses, args.stock, progress=plain)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(json.dumps({"cut_steps": res.cut_steps, "removed_m3": res.removed, "circle_steps": res.circle_steps,
                      "kernels_compiled": res.compiled, "kernels_loaded": res.loaded, "wall_s": round(res.wall, 2),
                      "spacing_m": defaults.RANKING_DEXEL_SPACING}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
