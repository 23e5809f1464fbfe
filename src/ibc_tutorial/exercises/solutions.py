# Reference solutions for the exercise notebooks (imported by the tests).


# =========================================================================== chapter 02: explicit policies
def ch02_beta_nll(alpha, beta, actions):
    """Eq. 1 of the DA-IBC paper: mean over the batch of the summed -log f((y + 1)/2; α, β)."""
    import torch

    y = ((actions + 1) / 2).clamp(1e-4, 1 - 1e-4)  # rescale to [0, 1]; keep logs finite at ±1
    log_b = torch.lgamma(alpha) + torch.lgamma(beta) - torch.lgamma(alpha + beta)
    log_f = (alpha - 1) * torch.log(y) + (beta - 1) * torch.log(1 - y) - log_b  # (B, D)
    return -log_f.sum(dim=1).mean()


def ch02_mdn_nll(logits, means, stds, actions):
    """-log Σ_k π_k Π_d N(y_d; μ_kd, σ_kd²), averaged over the batch, in log space."""
    import math

    import torch

    log_w = torch.log_softmax(logits, dim=1)  # (B, K)
    z = (actions[:, None, :] - means) / stds  # (B, K, D)
    log_n = (-0.5 * z**2 - torch.log(stds) - 0.5 * math.log(2 * math.pi)).sum(dim=2)  # (B, K)
    return -torch.logsumexp(log_w + log_n, dim=1).mean()


# =========================================================================== chapter 03: energy models and InfoNCE
def ch03_info_nce(pos_energy, neg_energy, weights=None):
    """Eqs. 2-3 of the DA-IBC paper (eq. 5 with weights): mean over the batch of w_i · (−log p̃_i)."""
    import torch

    logits = torch.cat([-pos_energy[:, None], -neg_energy], dim=1)  # (B, 1 + N), the expert first
    nll = torch.logsumexp(logits, dim=1) + pos_energy  # (B,): −log p̃_i, stable for large energies
    return nll.mean() if weights is None else (weights * nll).mean()


def ch03_soft_targets(candidates, actions, temperature):
    """Eq. 5 of the steering-EBM paper with the intended sign: softmax(−(a − a_GT)² / T) over the candidates."""
    import torch

    sq = ((candidates[None, :, :] - actions[:, None, :]) ** 2).sum(dim=-1)  # (B, K)
    return torch.softmax(-sq / temperature, dim=1)


def ch03_whiteness(commands, dt):
    """Eq. 2 of the steering-EBM paper: sqrt(mean((δP_i / δt)²)) over the D changes of a sequence."""
    import torch

    rate = torch.diff(torch.as_tensor(commands, dtype=torch.float64)) / dt  # (T - 1,)
    return float(torch.sqrt((rate**2).mean()))


# =========================================================================== chapter 04: DA-IBC counter-examples
def ch04_expert_negatives(expert_actions, batch_size, n_neg, sigma, generator=None):
    """Sec. 2.4 of the DA-IBC paper: expert actions drawn with replacement, plus N(0, σ²I)."""
    import torch

    m, d = expert_actions.shape
    idx = torch.randint(0, m, (batch_size, n_neg), generator=generator)  # (B, N), with replacement
    return expert_actions[idx] + sigma * torch.randn(batch_size, n_neg, d, generator=generator)


def ch04_grid_nll(pos_energy, grid_energy, cell_volume):
    """−log p(y|x) = E(x, y) + log Σ_g e^(−E(x, a_g)) + log ΔA, per sample: (B,)."""
    import math

    import torch

    return pos_energy + torch.logsumexp(-grid_energy, dim=1) + math.log(cell_volume)
