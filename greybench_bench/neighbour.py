"""A grey-box fit beside a busy neighbour: how much sharing the cores slows it (``bench friction``).

Each measurement runs in a fresh process so thread settings take effect before torch loads:

- *sized*: both the fit and the neighbour size their thread pools with
  :func:`identify.resources.configure_process` (usable cores, waiting threads sleep);
- *unsized*: library defaults (one spinning OpenMP thread per machine core in each process).

The neighbour keeps every usable core busy with its own torch thread pool (like a ranking or a
busy service next to the fit). With ``c`` usable cores and both processes wanting all of them, fair
sharing alone slows the fit about 2x; more than that is oversubscription.
"""
from __future__ import annotations

import os
import subprocess
import sys
import time
from typing import Any

#: Thread and wait settings removed from the children's environment for the *unsized* runs.
_THREAD_VARS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS",
                "OMP_WAIT_POLICY", "KMP_BLOCKTIME")

_FIT = """
import sys, time
if sys.argv[3] == "sized":
    from identify.resources import configure_process
    configure_process()
from identify.axis_limits import AxisLimits
from identify.models.greybox import GreyBoxLuGre
from identify.plant import PlantConfig, synthesize
from identify.records import validate_frame
from identify.trajectories import universal_trajectory

ut = universal_trajectory(AxisLimits(-3.2, 3.2, 2.1, 6.0, 60.0), duration=int(sys.argv[1]) / 1000.0)
rec = validate_frame(synthesize(ut.t, ut.q, ut.qd, ut.qdd, config=PlantConfig(static_curve="hump"), seed=1).frame,
                     "bench-neighbour")
est = GreyBoxLuGre(epochs=int(sys.argv[2]))
t0 = time.perf_counter()
est.fit(rec)
print(time.perf_counter() - t0)
"""

_BUSY = """
import sys, time
if sys.argv[2] == "sized":
    from identify.resources import configure_process
    configure_process()
import torch
a = torch.randn(256, 256, dtype=torch.float64)
end = time.time() + float(sys.argv[1])
while time.time() < end:  # bounded: ends by itself even if its parent is gone
    a = torch.tanh(a @ a / 256.0)
"""


def _env(mode: str) -> dict:
    env = {k: v for k, v in os.environ.items() if mode == "sized" or k not in _THREAD_VARS}
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


def fit_seconds(samples: int, epochs: int, mode: str, neighbour: bool, timeout: float = 900.0) -> float:
    """Seconds of one grey-box fit (``samples`` at 1 kHz, ``epochs``) in a fresh process, alone or
    beside a busy neighbour; ``mode`` 'sized' or 'unsized'."""
    env = _env(mode)
    busy = None
    if neighbour:
        busy = subprocess.Popen([sys.executable, "-c", _BUSY, str(timeout), mode], env=env,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(1.0)  # let it load torch and fill the cores
    try:
        r = subprocess.run([sys.executable, "-c", _FIT, str(samples), str(epochs), mode], env=env,
                           capture_output=True, text=True, timeout=timeout)
    finally:
        if busy is not None:
            busy.kill()
            busy.wait(10)
    if r.returncode != 0:
        raise RuntimeError(f"grey-box fit process failed: {r.stderr.strip().splitlines()[-1:]}")
    return float(r.stdout.strip().splitlines()[-1])


def measure(samples: int, epochs: int, advance=lambda n=1: None) -> dict:
    """Fit seconds alone and beside the neighbour, sized and unsized; slowdowns [-]."""
    from identify.resources import usable_cores

    res: dict[str, Any] = {"cores": usable_cores(), "samples": samples, "epochs": epochs}
    for mode in ("sized", "unsized"):
        alone = fit_seconds(samples, epochs, mode, neighbour=False)
        advance(1)
        busy = fit_seconds(samples, epochs, mode, neighbour=True)
        advance(1)
        res[mode] = {"alone_s": alone, "beside_s": busy, "slowdown": busy / alone}
    return res
