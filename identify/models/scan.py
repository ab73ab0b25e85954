"""Parallel associative scan of the linear recurrence ``z[k+1] = a[k]*z[k] + b[k]`` in torch.

The LuGre bristle state under the exact update (modelling notes 2) is such a
recurrence, so a whole record is computed in O(log n) vectorised levels instead of ``n``
Python steps, and autograd differentiates it like any other tensor code.

Method: the affine maps ``f_k(z) = a[k]*z + b[k]`` compose associatively,
``f_j o f_i = (a_j*a_i, a_j*b_i + b_j)``. A work-efficient (Blelloch-style) scan composes
neighbouring pairs, recurses on the half-length sequence of pair maps (log-depth doubling),
then fills in the even positions from the prefix before them. Only products and sums
appear -- never a division by a cumulative product -- so a factor ``a[k]`` that underflows
to 0 (fast sliding: ``exp(-s0*|qd|*dt/g)`` is tiny) simply forgets the past, as the physics
does, instead of producing ``0/0``. Work O(n), depth O(log n).
"""
from __future__ import annotations

import torch
from torch.nn.functional import pad


def _prefix_maps(A: torch.Tensor, B: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Inclusive prefix compositions ``f_k o ... o f_0`` as (A_k, B_k) along the last dim."""
    n = A.shape[-1]
    if n == 1:
        return A, B
    if n % 2:  # pad with the identity map (1, 0)
        A, B = pad(A, (0, 1), value=1.0), pad(B, (0, 1), value=0.0)
    Ae, Ao, Be, Bo = A[..., 0::2], A[..., 1::2], B[..., 0::2], B[..., 1::2]
    # maps of the pairs (2i, 2i+1); their prefixes are the odd positions' prefixes
    PA, PB = _prefix_maps(Ao * Ae, Ao * Be + Bo)
    # even position 2i: prefix up to 2i-1 (identity for i = 0) followed by map 2i
    EA = Ae * pad(PA[..., :-1], (1, 0), value=1.0)
    EB = Ae * pad(PB[..., :-1], (1, 0), value=0.0) + Be
    return (torch.stack([EA, PA], -1).flatten(-2)[..., :n],
            torch.stack([EB, PB], -1).flatten(-2)[..., :n])


def linear_recurrence(a: torch.Tensor, b: torch.Tensor, z0: torch.Tensor | float) -> torch.Tensor:
    """States of ``z[k+1] = a[k]*z[k] + b[k]`` from ``z[0] = z0``, by a log-depth parallel scan.

    Parameters
    ----------
    a, b : Tensor, shape (..., n)
        Coefficients per step along the last dimension (``a[k]`` maps ``z[k]`` to ``z[k+1]``).
    z0 : Tensor, shape (...), or float
        Initial state.

    Returns
    -------
    Tensor, shape (..., n + 1)
        ``z[0], z[1], ..., z[n]``. Differentiable in ``a``, ``b`` and ``z0``.
    """
    z0 = torch.as_tensor(z0, dtype=a.dtype, device=a.device).expand(a.shape[:-1])
    if a.shape[-1] == 0:
        return z0.unsqueeze(-1)
    A, B = _prefix_maps(a, b)
    return torch.cat([z0.unsqueeze(-1), A * z0.unsqueeze(-1) + B], dim=-1)


def linear_recurrence_loop(a: torch.Tensor, b: torch.Tensor, z0: torch.Tensor | float) -> torch.Tensor:
    """The same recurrence step by step in Python (reference and benchmark baseline only)."""
    z = [torch.as_tensor(z0, dtype=a.dtype, device=a.device).expand(a.shape[:-1])]
    for k in range(a.shape[-1]):
        z.append(a[..., k] * z[-1] + b[..., k])
    return torch.stack(z, dim=-1)
