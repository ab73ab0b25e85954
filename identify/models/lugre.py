"""The conventional LuGre model identified by a genetic algorithm (paper 2.2.1, ref. [38]).

LuGre: ``tau_F = s0*z + s1*zdot + nu*qd``, ``zdot = qd - s0*|qd|*z/g(qd)`` with the
Stribeck static curve ``g(qd) = fc + (fs - fc)*exp(-|qd/vs|^delta)`` (paper eqs. 5, 7-9),
integrated with the exact bristle update (:mod:`identify.models.lugre_kernel`).

Identification, as the paper's conventional method but on one record:

1. A genetic algorithm (pygad) searches the parameters that enter nonlinearly --
   log10 s0, fc, fs - fc, log10 vs, delta -- inside box bounds given as the GA's gene space
   (bounds and positivity are constraints of the search, never clipping afterwards).
   For each individual the parameters that enter linearly (s1, nu and, without ``tau_rb``,
   the inertia J and offset c) are solved exactly by sign-constrained least squares
   (variable projection), so the GA explores 5 dimensions instead of 9. The whole
   population's fitness is one numba-parallel call per generation.
2. A local bounded least-squares polish (scipy ``least_squares``, trust-region reflective)
   of all parameters together, starting from the GA's best individual.

Seeded: the same record and seed give the same parameters.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pygad
from scipy.optimize import least_squares

from identify.models.base import FrictionModel
from identify.models.lugre_kernel import lugre_stribeck, population_sse
from identify.models.static_curves import stribeck
from identify.records import AxisRecord


@dataclass(frozen=True)
class LuGreTable:
    """A LuGre friction model in tabulated form, for simulators (e.g. the axis servo).

    Attributes
    ----------
    s0 : float
        Bristle stiffness [Nm/rad].
    s1 : float
        Bristle damping [Nm s/rad].
    nu : float
        Viscous coefficient [Nm s/rad].
    v : ndarray
        Velocity grid [rad/s], increasing, symmetric about zero.
    g : ndarray
        Static friction level g(v) [Nm] on the grid (> 0).
    """

    s0: float
    s1: float
    nu: float
    v: np.ndarray
    g: np.ndarray

    def level(self, v: np.ndarray) -> np.ndarray:
        """g(v) by linear interpolation, held constant beyond the grid [Nm]."""
        return np.interp(v, self.v, self.g)


#: Bristle time constants ``level / (s0 * v_max)`` [s] searched: the time the joint takes at
#: top speed to cross its pre-sliding deflection. On the synthetic axis (level ~ 7 Nm, top speed
#: ~ 1.7 rad/s) these are the former fixed bounds 1e2..1e6 Nm/rad.
BRISTLE_TIME = (4e-6, 4e-2)
#: Stribeck velocity range relative to the top speed [-] (former 1e-3..1 rad/s at ~2 rad/s).
STRIBECK_SHARE = (5e-4, 0.5)


def torque_level(y: np.ndarray) -> float:
    """Friction-level scale of a target torque [Nm]: 1.5 x its 99th percentile magnitude."""
    return 1.5 * float(np.percentile(np.abs(y), 99)) + 1e-300


def relative_bounds(y: np.ndarray, qd: np.ndarray) -> tuple[tuple[float, float], tuple[float, float]]:
    """Search ranges of s0 [Nm/rad] and vs [rad/s] from the record's own scales (top speed
    ``v_max`` and :func:`torque_level`): ``s0 = level / (v_max * tau_b)`` for the bristle times
    :data:`BRISTLE_TIME` and ``vs = v_max *`` :data:`STRIBECK_SHARE`. Scaling the torque or the
    position unit (a linear axis in m) scales the ranges with the parameters."""
    v_max = float(np.max(np.abs(qd))) or 1.0
    level = torque_level(y)
    s0 = (level / (v_max * BRISTLE_TIME[1]), level / (v_max * BRISTLE_TIME[0]))
    return s0, (v_max * STRIBECK_SHARE[0], v_max * STRIBECK_SHARE[1])


def velocity_grid(v_max: float, n: int = 513) -> np.ndarray:
    """Symmetric grid on [-v_max, v_max], dense near zero where the Stribeck dip lives."""
    half = np.geomspace(1e-5, v_max, (n - 1) // 2)
    return np.concatenate([-half[::-1], [0.0], half])


class LuGre(FrictionModel):
    """Conventional LuGre friction model, GA + least-squares identification.

    Parameters
    ----------
    population : int
        GA individuals per generation.
    generations : int
        GA generations.
    seed : int
        Random seed of the GA.
    polish : bool
        Run the local least-squares polish after the GA.
    s0_bounds : tuple of float, optional
        Search range of s0 [Nm/rad]. None (default): relative to the record, see
        :func:`relative_bounds` (so a record in other units, or of a linear axis, is
        searched alike).
    vs_bounds : tuple of float, optional
        Search range of the Stribeck velocity [rad/s]; None: relative to the record.
    delta_bounds : tuple of float
        Search range of the Stribeck exponent [-].
    """

    name = "lugre"
    units = {"s0": "Nm/rad", "s1": "Nm s/rad", "nu": "Nm s/rad", "fc": "Nm", "fs": "Nm", "vs": "rad/s",
             "delta": "-", "J": "kg m^2", "c": "Nm"}

    def __init__(self, population: int = 48, generations: int = 50, seed: int = 0, polish: bool = True,
                 s0_bounds: tuple[float, float] | None = None, vs_bounds: tuple[float, float] | None = None,
                 delta_bounds: tuple[float, float] = (0.5, 3.0)):
        self.population = population
        self.generations = generations
        self.seed = seed
        self.polish = polish
        self.s0_bounds = None if s0_bounds is None else tuple(s0_bounds)
        self.vs_bounds = None if vs_bounds is None else tuple(vs_bounds)
        self.delta_bounds = tuple(delta_bounds)

    # ---- identification --------------------------------------------------------------
    def _gene_space(self, y: np.ndarray, qd: np.ndarray) -> list[dict]:
        level = torque_level(y)
        s0_rel, vs_rel = relative_bounds(y, qd)
        s0b = self.s0_bounds or s0_rel
        vsb = self.vs_bounds or vs_rel
        return [{"low": np.log10(s0b[0]), "high": np.log10(s0b[1])},
                {"low": 0.0, "high": level},
                {"low": 0.0, "high": level},
                {"low": np.log10(vsb[0]), "high": np.log10(vsb[1])},
                {"low": self.delta_bounds[0], "high": self.delta_bounds[1]}]

    def _fit(self, record: AxisRecord) -> None:
        qd = np.ascontiguousarray(record.qd, dtype=float)
        # with tau_rb only the offset c is co-identified: a zero acceleration column keeps the
        # same linear solve (J then stays 0 and is not reported)
        qdd = np.ascontiguousarray(record.qdd if self.rigid_ else np.zeros(record.n), dtype=float)
        dt = np.ascontiguousarray(record.dt, dtype=float)
        y = np.ascontiguousarray(record.friction_target, dtype=float)
        rigid = True
        n = float(y.size)

        def fitness(_ga, solutions, _idx):
            sse, _ = population_sse(np.ascontiguousarray(np.atleast_2d(solutions), dtype=float), qd, qdd, dt, y, rigid)
            return list(-sse / n)

        space = self._gene_space(y, qd)
        ga = pygad.GA(num_generations=self.generations, num_parents_mating=max(4, self.population // 3),
                      fitness_func=fitness, fitness_batch_size=self.population, sol_per_pop=self.population,
                      num_genes=5, gene_space=space, gene_type=float, parent_selection_type="tournament",
                      K_tournament=3, keep_elitism=2, crossover_type="uniform", mutation_type="random",
                      mutation_probability=0.2, random_seed=self.seed, suppress_warnings=True)
        ga.run()
        best, _, _ = ga.best_solution(pop_fitness=ga.last_generation_fitness)
        _, lin = population_sse(np.ascontiguousarray(best[None, :], dtype=float), qd, qdd, dt, y, rigid)
        x = np.concatenate([best, lin[0, :4]])
        self.ga_generations_ = int(ga.generations_completed)
        if self.polish:
            x = self._polish(x, qd, qdd, dt, y, rigid, space)
        self.params_ = self._unpack(x, bool(self.rigid_))

    @staticmethod
    def _unpack(x: np.ndarray, rigid: bool) -> dict[str, float]:
        p = {"s0": 10.0 ** x[0], "fc": x[1], "fs": x[1] + x[2], "vs": 10.0 ** x[3], "delta": x[4],
             "s1": x[5], "nu": x[6]}
        if rigid:
            p.update(J=x[7], c=x[8])
        elif x.size > 8:
            p["c"] = x[8]  # the torque offset (with tau_rb; base module)
        return {k: float(v) for k, v in p.items()}

    def _polish(self, x0, qd, qdd, dt, y, rigid, space):
        lo = [s["low"] for s in space] + [0.0, 0.0] + ([0.0, -np.inf] if rigid else [])
        hi = [s["high"] for s in space] + [np.inf, np.inf] + ([np.inf, np.inf] if rigid else [])
        lo, hi = np.array(lo), np.array(hi)
        def pad(b):
            return 1e-9 * (np.abs(np.where(np.isfinite(b), b, 0.0)) + 1.0)
        x0 = np.clip(x0, lo + pad(lo), hi - pad(hi))
        z = np.empty_like(qd)

        def residual(x):
            f = lugre_stribeck(qd, dt, 10.0 ** x[0], x[5], x[6], x[1], x[1] + x[2], 10.0 ** x[3], x[4], z)
            if rigid:
                f = f + x[7] * qdd + x[8]
            return f - y

        res = least_squares(residual, x0, bounds=(lo, hi), method="trf", x_scale="jac", max_nfev=200)
        return res.x if np.sum(res.fun**2) <= np.sum(residual(x0) ** 2) else x0

    # ---- prediction ------------------------------------------------------------------
    def _friction(self, record: AxisRecord) -> np.ndarray:
        p = self.params_
        z = np.empty(record.n)
        return lugre_stribeck(np.ascontiguousarray(record.qd, dtype=float), np.ascontiguousarray(record.dt),
                              p["s0"], p["s1"], p["nu"], p["fc"], p["fs"], p["vs"], p["delta"], z) + self.offset()

    def static_curve(self, v: np.ndarray) -> np.ndarray:
        """Fitted static level g(v) [Nm]."""
        self._check_fitted()
        p = self.params_
        return stribeck(v, p["fc"], p["fs"], p["vs"], p["delta"])

    def as_lugre_table(self, v_max: float, n: int = 513) -> LuGreTable:
        """The fitted model as a :class:`LuGreTable` on [-v_max, v_max] rad/s."""
        v = velocity_grid(v_max, n)
        p = self.params_
        return LuGreTable(s0=p["s0"], s1=p["s1"], nu=p["nu"], v=v, g=self.static_curve(v))
