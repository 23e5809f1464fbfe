"""Langevin MCMC inference (the original IBC paper), its polynomial step-size schedule and the ULA option."""

import pytest
import torch

import ibc_tutorial.optimizers.langevin
from ibc_tutorial.optimizers.common import bounds
from ibc_tutorial.optimizers.langevin import (
    LangevinConfig,
    langevin,
    langevin_trace,
    polynomial_schedule,
)


def test_polynomial_schedule_matches_the_ibc_formula():
    n = 25
    rates = [polynomial_schedule(k, n) for k in range(n)]
    assert rates[0] == pytest.approx(1e-1) and rates[-1] == pytest.approx(1e-5)
    for k, r in enumerate(rates):  # (init − final)(1 − k/(n−1))^2 + final
        assert r == pytest.approx((1e-1 - 1e-5) * (1 - k / 24) ** 2 + 1e-5)
    assert all(a > b for a, b in zip(rates[:-1], rates[1:], strict=True))
    assert polynomial_schedule(0, 1) == pytest.approx(1e-1)
    with pytest.raises(ValueError, match="step"):
        polynomial_schedule(25, 25)


def test_langevin_descends_to_a_quadratic_minimum():
    def energy(y):
        return ((y - torch.tensor([0.3, -0.4])) ** 2).sum(-1) * 20  # (N, 2) -> (N,)

    g = torch.Generator().manual_seed(0)
    experts = torch.zeros(3, 2)
    tr = langevin_trace(
        energy, experts, LangevinConfig(n_samples=256, n_iters=50, noise_scale=0.0), generator=g
    )
    final = tr.samples[-1]
    assert (final - torch.tensor([0.3, -0.4])).abs().max() < 0.02
    torch.testing.assert_close(tr.action, torch.tensor([0.3, -0.4]), atol=0.02, rtol=0)
    assert tr.energy_evaluations == 256 * 51 and tr.gradient_evaluations == 256 * 50
    assert len(tr.samples) == 51 and len(tr.step_sizes) == 50


def test_one_step_is_the_reference_update():
    """y ← clip(y − clip(ε(½ dE/dy + noise·n), ±0.1·half-range), low, high) with n ~ N(0, I)."""
    c = torch.tensor([0.5])

    def energy(y):
        return ((y - c) ** 2).sum(-1)  # dE/dy = 2 (y − c)

    experts = torch.zeros(2, 1)
    g1 = torch.Generator().manual_seed(3)
    tr = langevin_trace(
        energy,
        experts,
        LangevinConfig(n_samples=64, n_iters=1, step_init=0.05, noise_scale=1.0),
        generator=g1,
    )
    y0, y1 = tr.samples
    g2 = torch.Generator().manual_seed(3)
    _ = torch.rand(1, 64, 1, generator=g2)  # the uniform initialisation
    noise = torch.randn(1, 64, 1, generator=g2)[0]
    delta = (0.05 * (0.5 * 2 * (y0 - c) + noise)).clamp(-0.1, 0.1)
    torch.testing.assert_close(y1, (y0 - delta).clamp(-1, 1))


def test_langevin_stays_in_bounds_and_is_reproducible():
    def energy(y):
        return -5 * y.sum(-1)  # pulls towards +inf

    experts = torch.zeros(2, 1)
    c = LangevinConfig(n_samples=128, n_iters=30, step_init=0.5, delta_clip=1.0)
    tr = langevin_trace(energy, experts, c, generator=torch.Generator().manual_seed(1))
    assert all(s.min() >= -1 and s.max() <= 1 for s in tr.samples)
    a = langevin(energy, experts, c, generator=torch.Generator().manual_seed(1))
    assert torch.equal(a, tr.action) and float(a) == 1.0


def test_langevin_batched_form_and_errors():
    centres = torch.tensor([[-0.5], [0.6]])

    def energy(y):
        return 20 * ((y - centres[:, None, :]) ** 2).sum(-1)  # (B, N, 1) -> (B, N)

    acts = langevin(
        energy,
        torch.zeros(2, 1),
        LangevinConfig(n_samples=128, n_iters=60),
        n_obs=2,
        generator=torch.Generator().manual_seed(2),
    )
    torch.testing.assert_close(acts, centres, atol=0.05, rtol=0)

    def e(y):
        return (y**2).sum(-1)

    with pytest.raises(ValueError, match="n_samples"):
        LangevinConfig(n_samples=0)
    with pytest.raises(ValueError, match="low must be < high"):
        LangevinConfig(low=1.0, high=-1.0)
    with pytest.raises(ValueError, match="step_init"):
        LangevinConfig(step_init=0.0)
    with pytest.raises(ValueError, match="noise"):
        LangevinConfig(noise="sqrt")
    with pytest.raises(ValueError, match="action dimension"):
        langevin(e, torch.zeros(2, 1), LangevinConfig(low=[-1, -1, -1], high=1.0))
    with pytest.raises(ValueError, match="config must be a LangevinConfig"):
        langevin(e, torch.zeros(2, 1), dict(n_samples=8))


def test_single_form_is_batched_with_b_equal_1_and_the_optimizer_protocol():
    def energy(y):
        return 20 * ((y - 0.3) ** 2).sum(-1)  # (N, 1) -> (N,)

    c = LangevinConfig(n_samples=64, n_iters=10, select="sample")
    a = langevin(energy, torch.zeros(2, 1), c, generator=torch.Generator().manual_seed(3))
    b = langevin(
        lambda y: energy(y[0])[None],
        torch.zeros(2, 1),
        c,
        n_obs=1,
        generator=torch.Generator().manual_seed(3),
    )
    assert a.shape == (1,) and b.shape == (1, 1) and torch.equal(a, b[0])

    class Model:  # E(x, y) = 20 (y − x)²
        def embed(self, obs):
            return obs

        def energy_from_embedding(self, z, actions):
            return 20 * ((actions - z[:, None, :]) ** 2).sum(-1)  # (B, N)

    # on a model: the observations embedded once, every chain scored against its own embedding
    model, obs = Model(), torch.tensor([[-0.5], [0.6]])
    z = model.embed(obs)  # (B, E)
    found = langevin(
        lambda y: model.energy_from_embedding(z, y),
        torch.zeros(2, 1),
        LangevinConfig(n_samples=128, n_iters=60),
        n_obs=len(z),
        generator=torch.Generator().manual_seed(2),
    )  # (B, 1)
    torch.testing.assert_close(found, obs, atol=0.05, rtol=0)


def test_ula_noise_samples_the_boltzmann_distribution_and_ibc_noise_does_not():
    """E = y² / (2 s²) is the Gaussian N(0, s²): ULA's chains spread like it; the reference's collapse."""
    s = 0.2

    def energy(y):
        return (y[:, 0] ** 2) / (2 * s * s)  # (N, 1) -> (N,)

    base = dict(
        n_samples=4000, n_iters=300, step_init=0.004, step_final=0.004, delta_clip=10.0, low=-5.0, high=5.0
    )
    stds = {}
    for noise in ("ibc", "ula"):
        tr = langevin_trace(
            energy,
            torch.zeros(2, 1),
            LangevinConfig(**base, noise=noise),
            generator=torch.Generator().manual_seed(0),
        )
        assert tr.config.noise == noise
        stds[noise] = float(tr.samples[-1].std())
    # ULA with gradient step η = ε/2 = 0.002 and noise √(2η): stationary variance s² / (1 − η / (2 s²)) ≈ s²
    expected = s / (1 - 0.002 / (2 * s * s)) ** 0.5
    assert abs(stds["ula"] - expected) < 0.05 * expected
    # the reference's noise ε·n: variance ε² / (2η/s² − (η/s²)²), a spread of about 0.013, far below s
    assert stds["ibc"] < 0.25 * s
    # the reference's numbers are unchanged by the option's existence: "ibc" is the default
    assert LangevinConfig().noise == "ibc"


def test_one_ula_step_is_the_textbook_update():
    """y ← clip(y − (ε/2) dE/dy − √ε n): ULA with gradient step η = ε/2 and noise √(2η)."""
    c = torch.tensor([0.5])

    def energy(y):
        return ((y - c) ** 2).sum(-1)  # dE/dy = 2 (y − c)

    tr = langevin_trace(
        energy,
        torch.zeros(2, 1),
        LangevinConfig(n_samples=64, n_iters=1, step_init=0.05, delta_clip=10.0, noise="ula"),
        generator=torch.Generator().manual_seed(3),
    )
    y0, y1 = tr.samples
    g2 = torch.Generator().manual_seed(3)
    _ = torch.rand(1, 64, 1, generator=g2)  # the uniform initialisation
    noise = torch.randn(1, 64, 1, generator=g2)[0]
    torch.testing.assert_close(y1, (y0 - 0.05 * 0.5 * 2 * (y0 - c) - 0.05**0.5 * noise).clamp(-1, 1))


def test_the_noise_comes_from_the_generator_and_goes_to_the_actions_device(monkeypatch):
    """The noise is drawn on the generator's device (the CPU) and moved to the chains' device, as DFO's is:
    "another device" simulated with torch's meta device (shapes, no values, so the finiteness check of the
    energies is switched off); the CPU run is unchanged (``test_one_step_is_the_reference_update``)."""
    monkeypatch.setattr(ibc_tutorial.optimizers.langevin, "energies", lambda energy_fn, y: energy_fn(y))

    def energy(y):
        return 20 * ((y - 0.3) ** 2).sum(-1)  # (B, N, D) -> (B, N)

    c = LangevinConfig(n_samples=16, n_iters=4)
    lo, hi = bounds(c.low, c.high, 2)  # on the CPU, as ``langevin`` makes them
    y = torch.rand(3, 16, 2, generator=torch.Generator().manual_seed(0)) * 2 - 1  # (B, N, D)
    g_cpu, g_meta = torch.Generator().manual_seed(4), torch.Generator().manual_seed(4)
    on_cpu, _ = ibc_tutorial.optimizers.langevin._langevin_core(energy, y, c, lo, hi, g_cpu, record=False)
    on_meta, _ = ibc_tutorial.optimizers.langevin._langevin_core(
        energy, y.to("meta"), c, lo, hi, g_meta, record=False
    )
    assert (
        on_cpu.device.type == "cpu"
        and on_meta.device.type == "meta"
        and on_meta.shape == on_cpu.shape == (3, 2)
    )
    assert torch.equal(g_cpu.get_state(), g_meta.get_state())  # the same draws, from the CPU generator
