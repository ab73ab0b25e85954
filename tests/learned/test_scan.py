"""The associative scan against the step-by-step recurrence and the numba bristle kernel."""
import numpy as np
import pytest
import torch

from identify.models.greybox import bristle_recurrence
from identify.models.lugre_kernel import bristle_states
from identify.models.scan import linear_recurrence, linear_recurrence_loop


@pytest.mark.parametrize("n", [1, 2, 3, 7, 64, 1000, 4097])
def test_scan_matches_loop(n):
    gen = torch.Generator().manual_seed(n)
    a = torch.rand(n, generator=gen, dtype=torch.float64)
    b = torch.randn(n, generator=gen, dtype=torch.float64)
    z = linear_recurrence(a, b, 0.3)
    ref = linear_recurrence_loop(a, b, 0.3)
    assert z.shape == (n + 1,)
    torch.testing.assert_close(z, ref, rtol=1e-12, atol=1e-12)


def test_scan_batched_and_underflow():
    a = torch.tensor([[0.5, 0.0, 0.9, 1e-300, 0.7], [1.0, 1.0, 1.0, 1.0, 1.0]], dtype=torch.float64)
    a[0, 3] = a[0, 3] * 1e-300  # underflows to exactly 0
    b = torch.ones_like(a)
    z = linear_recurrence(a, b, torch.tensor([2.0, -1.0], dtype=torch.float64))
    torch.testing.assert_close(z, linear_recurrence_loop(a, b, torch.tensor([2.0, -1.0], dtype=torch.float64)))
    assert torch.isfinite(z).all()
    assert z[1, -1] == 4.0  # pure integration: -1 + 5


def test_scan_gradient_matches_loop():
    gen = torch.Generator().manual_seed(0)
    a = torch.rand(300, generator=gen, dtype=torch.float64, requires_grad=True)
    b = torch.randn(300, generator=gen, dtype=torch.float64, requires_grad=True)
    w = torch.randn(301, generator=gen, dtype=torch.float64)
    ga = torch.autograd.grad((linear_recurrence(a, b, 0.1) * w).sum(), (a, b))
    gl = torch.autograd.grad((linear_recurrence_loop(a, b, 0.1) * w).sum(), (a, b))
    for x, y in zip(ga, gl, strict=True):
        torch.testing.assert_close(x, y, rtol=1e-10, atol=1e-12)


def test_bristle_scan_matches_numba_kernel():
    """The exact LuGre bristle update by scan equals the numba kernel to 1e-6 relative."""
    rng = np.random.default_rng(3)
    n = 20_000
    t = np.arange(n) * 1e-3
    qd = 1.2 * np.sin(2 * np.pi * 0.5 * t) * np.exp(-t / 8) + 1e-4 * rng.standard_normal(n)
    qd[5000:5010] = 0.0  # standstill: a = 1, b = 0
    dt = np.full(n, 1e-3)
    g = 2.0 + 0.8 * np.exp(-np.abs(qd / 0.05) ** 2)
    for s0 in (1e3, 1.7e4, 1e6):  # 1e6: exp(-s0|v|dt/g) underflows to 0 at speed
        z_ref = bristle_states(qd, dt, g, s0)
        w0 = torch.tensor(s0 * z_ref[0], dtype=torch.float64)
        w = bristle_recurrence(*(torch.tensor(x) for x in (qd, dt, g)), torch.tensor(s0, dtype=torch.float64), w0)
        z = w.numpy() / s0
        scale = np.max(np.abs(z_ref))
        assert np.max(np.abs(z - z_ref)) <= 1e-6 * scale
        np.testing.assert_allclose(z[np.abs(z_ref) > 1e-3 * scale], z_ref[np.abs(z_ref) > 1e-3 * scale], rtol=1e-6)


def test_greybox_scan_forward_equals_recurrent_loop():
    from identify.models.greybox import GreyBoxLuGreNet, forward_recurrent

    n = 400
    t = torch.arange(n, dtype=torch.float64) * 1e-3
    qd = 0.8 * torch.sin(2 * torch.pi * 3 * t) * torch.exp(-t)
    qdd = torch.gradient(qd, spacing=1e-3)[0]
    dt = torch.full((n,), 1e-3, dtype=torch.float64)
    net = GreyBoxLuGreNet(1.0, 2.0, 10.0, s0=2e4, s1=5.0, nu=0.4, J=0.5, c=0.05)
    with torch.no_grad():
        torch.testing.assert_close(net(qd, qdd, dt).total, forward_recurrent(net, qd, qdd, dt), rtol=1e-10, atol=1e-12)
