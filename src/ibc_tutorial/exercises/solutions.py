"""Reference solutions of the exercise notebooks, one function per checked exercise (used by the tests).

Each is the shortest correct answer the checker accepts.
"""

import math

import numpy as np
import torch

from ibc_tutorial.driving.energy_profiles import valleys
from ibc_tutorial.kde import inverse_density_weights, kde_density


# =========================================================================== chapter 01: the tree
def ch01_best_constant_mse(actions):
    """The constant c minimising (1/N) Σ (a_i - c)^2: setting the derivative -2/N Σ (a_i - c) to zero
    gives the mean."""
    return float(actions.mean())


def ch01_hits_tree(car_xy, tree_xy, car_radius, tree_radius):
    """(B,) bool: the discs overlap when the centres are closer than the sum of the radii."""
    return (car_xy - tree_xy).norm(dim=1) < car_radius + tree_radius


def ch01_swerve(y):
    """(E,) the largest move towards the side road, to the right (-y), since the first time step
    (>= 0, as t = 0 counts too)."""
    return y[:, 0] - y.min(dim=1).values


def ch01_predict_mae_side(n_right, n_left):
    """Where the constant of least mean absolute error lies: a median, in the bigger mode."""
    if n_right == n_left:
        return "anywhere in the gap"
    return "right" if n_right > n_left else "left"


# =========================================================================== chapter 02: explicit policies
def ch02_beta_can_represent(shape):
    """A Beta has at most one interior peak; flat (alpha = beta = 1) and U-shapes (both < 1) exist."""
    return shape != "two peaks inside"


def ch02_beta_nll(alpha, beta, actions):
    """Eq. 1 of the DA-IBC paper: mean over the batch of the summed -log f((y + 1)/2; α, β)."""

    y = ((actions + 1) / 2).clamp(1e-4, 1 - 1e-4)  # rescale to [0, 1]; keep logs finite at ±1
    log_b = torch.lgamma(alpha) + torch.lgamma(beta) - torch.lgamma(alpha + beta)
    log_f = (alpha - 1) * torch.log(y) + (beta - 1) * torch.log(1 - y) - log_b  # (B, D)
    return -log_f.sum(dim=1).mean()


def ch02_mdn_nll(logits, means, stds, actions):
    """-log Σ_k π_k Π_d N(y_d; μ_kd, σ_kd²), averaged over the batch, in log space."""

    log_w = torch.log_softmax(logits, dim=1)  # (B, K)
    z = (actions[:, None, :] - means) / stds  # (B, K, D)
    log_n = (-0.5 * z**2 - torch.log(stds) - 0.5 * math.log(2 * math.pi)).sum(dim=2)  # (B, K)
    return -torch.logsumexp(log_w + log_n, dim=1).mean()


# =========================================================================== chapter 03: energy models
def ch03_info_nce(pos_energy, neg_energy, weights=None):
    """Eqs. 2-3 of the DA-IBC paper (eq. 5 with weights): mean over the batch of w_i · (−log p̃_i)."""

    logits = torch.cat([-pos_energy[:, None], -neg_energy], dim=1)  # (B, 1 + N), the expert first
    nll = torch.logsumexp(logits, dim=1) + pos_energy  # (B,): −log p̃_i, stable for large energies
    return nll.mean() if weights is None else (weights * nll).mean()


def ch03_soft_targets(candidates, actions, temperature):
    """Eq. 5 of the steering-EBM paper with the intended sign: softmax(−(a − a_GT)² / T) over the
    candidates."""

    sq = ((candidates[None, :, :] - actions[:, None, :]) ** 2).sum(dim=-1)  # (B, K)
    return torch.softmax(-sq / temperature, dim=1)


def ch03_whiteness(commands, dt):
    """Eq. 2 of the steering-EBM paper: sqrt(mean((δP_i / δt)²)) over the D changes of a sequence."""

    rate = torch.diff(torch.as_tensor(commands, dtype=torch.float64)) / dt  # (T - 1,)
    return float(torch.sqrt((rate**2).mean()))


def ch03_predict_decision():
    """The chapter's finding, predicted for 70 % right-passing experts (modes about ±0.9 where they
    decide): MSE gives the weighted mean, MAE the median (in the majority mode), the argmin the
    deeper valley (the majority side), a draw the experts' share."""
    return {"mse": 0.7 * 0.88 - 0.3 * 0.88, "mae": 0.85, "argmin": "right", "sample_right": 0.7}


# =========================================================================== chapter 04: counter-examples
def ch04_expert_negatives(expert_actions, batch_size, n_neg, sigma, generator=None):
    """Sec. 2.4 of the DA-IBC paper: expert actions drawn with replacement, plus N(0, σ²I)."""

    m, d = expert_actions.shape
    idx = torch.randint(0, m, (batch_size, n_neg), generator=generator)  # (B, N), with replacement
    return expert_actions[idx] + sigma * torch.randn(batch_size, n_neg, d, generator=generator)


def ch04_grid_nll(pos_energy, grid_energy, cell_volume):
    """−log p(y|x) = E(x, y) + log Σ_g e^(−E(x, a_g)) + log ΔA, per sample: (B,)."""

    return pos_energy + torch.logsumexp(-grid_energy, dim=1) + math.log(cell_volume)


def ch04_predicted_shares(valid_actions, expert_actions, sigma):
    """Shares ∝ 1/q(y) at K equally likely valid actions, q the expert actions blurred by N(0, σ²I)."""

    q = kde_density(valid_actions, expert_actions, sigma)  # (K,) the counter-examples' density
    return (1 / q) / (1 / q).sum()


# =========================================================================== chapter 05: KDE weighting
def ch05_kde_1d(x, data, h):
    """Eq. 4 of the DA-IBC paper: ĝ(x) = 1/(N h) Σ_j K((x − x_j)/h) with the Gaussian kernel, for every x."""

    u = (x[:, None] - data[None, :]) / h  # (Q, N)
    k = torch.exp(-0.5 * u**2) / math.sqrt(2 * math.pi)  # K(u)
    return k.sum(dim=1) / (len(data) * h)  # (Q,)


def ch05_inverse_weights(actions, h):
    """w_i ∝ 1/ĝ(y_i) (eq. 5), normalised to sum to 1, with ĝ the product-kernel KDE over the actions
    themselves."""

    d = actions.shape[1]
    u = (actions[:, None, :] - actions[None, :, :]) / h  # (M, M, D)
    k = torch.exp(-0.5 * (u**2).sum(-1)) / (2 * math.pi) ** (d / 2)  # Π_d K(u_d)
    g = k.sum(dim=1) / (len(actions) * h**d)  # (M,) ĝ(y_i)
    w = 1.0 / g
    return w / w.sum()


def ch05_choose_bandwidth(actions, rare, candidates, min_ess):
    """Among the candidates whose weights keep 1/Σ w_i² >= min_ess, the h with the most rare samples."""

    best, best_share = None, -1.0
    for h in candidates:
        w = inverse_density_weights(actions, h)  # (M,) summing to 1
        ess = float(1 / (w**2).sum())  # effective number of samples
        share = float(w[rare].sum())  # expected share of rare samples in a weighted minibatch
        if ess >= min_ess and share > best_share:
            best, best_share = h, share
    return best


# =========================================================================== chapter 06: DFO inference
def ch06_dfo_step(samples, energies, sigma, low, high, generator):
    """Lines 5 and 7-10 of Algorithm 1: softmax of −E, resample N with replacement, add N(0, σ), clip."""

    p = torch.softmax(-energies, dim=0)  # line 5: p̃_i
    idx = torch.multinomial(p, len(samples), replacement=True, generator=generator)  # lines 7-8
    new = samples[idx] + sigma * torch.randn(samples.shape, generator=generator)  # line 9
    return new.clamp(low, high)  # line 10


def ch06_select_action(samples, energies, select, generator):
    """Line 14 of Algorithm 1 ("sample": ŷ ~ Categorical({ỹ_i}, {p̃_i})) or the original IBC's "argmax"."""

    p = torch.softmax(-energies, dim=0)
    if select == "argmax":
        return samples[int(p.argmax())]
    return samples[int(torch.multinomial(p, 1, generator=generator))]


def ch06_shallow_share(delta, k, r):
    """Share of DFO calls ending in the shallower valley: r e^{−kΔ} / (1 + r e^{−kΔ}) (p(y|x)^k)."""

    x = r * math.exp(-k * delta)
    return x / (1 + x)


# =========================================================================== chapter 07: the car and the town
def ch07_yaw_rate(speed, steer):
    """Kinematic bicycle: omega = -v tan(delta_max steer) / L (positive steer turns right, clockwise)."""

    return -speed * math.tan(0.6 * steer) / 2.9


def ch07_pid_outputs(errors, kp, ki, kd, dt):
    """u_t = kp e_t + ki sum_k e_k dt + kd (e_t - e_{t-1}) / dt, the derivative 0 at the first step."""
    out, integral, prev = [], 0.0, None
    for e in errors:
        integral += e * dt
        deriv = 0.0 if prev is None else (e - prev) / dt
        prev = e
        out.append(kp * e + ki * integral + kd * deriv)
    return out


def ch07_ran_red_light(rear_before, rear_after, entry, direction, state):
    """True if the rear crossed the line forwards, within the lane (2 m each side), while red (state 2)."""

    right = np.array([direction[1], -direction[0]])
    s0 = float((rear_before - entry) @ direction)
    s1 = float((rear_after - entry) @ direction)
    lateral = float((rear_after - entry) @ right)
    return bool(state == 2 and s0 < 0 <= s1 and abs(lateral) <= 2.0)


def ch07_world_to_bev(x, y, car_x, car_y, car_yaw):
    """(row, col) of a world point in the 192 view: 5 px/m, heading up, the car at row 152, column 96."""

    ahead = (x - car_x) * math.cos(car_yaw) + (y - car_y) * math.sin(car_yaw)
    right = (x - car_x) * math.sin(car_yaw) - (y - car_y) * math.cos(car_yaw)
    return 152 - 5 * ahead, 96 + 5 * right


def ch07_expert_stops(state, gap_m, speed):
    """Within 9.5 m: red stops, green goes, yellow stops if v^2 / (2 gap) <= 4 m/s^2."""
    if gap_m > 9.5 or state == 0:
        return False
    if state == 2:
        return True
    return gap_m > 0 and speed * speed / (2 * gap_m) <= 4.0


# =========================================================================== chapter 08: training the agents
def ch08_episode_score(xy, crossed):
    """The path's length (a sum over steps) x 0.7 ** (stop lines crossed at red, state 2)."""

    distance = float(np.hypot(*np.diff(xy, axis=0).T).sum())  # metres, step by step
    return distance * 0.7 ** int((np.asarray(crossed) == 2).sum())


def ch08_unseen_share(probs, batch_size):
    """Mean over samples of (1 - p_i) ** n, n = ceil(M / B) B draws with replacement in one epoch."""

    n = math.ceil(len(probs) / batch_size) * batch_size
    return float(((1 - np.asarray(probs, dtype=float)) ** n).mean())


def ch08_recipe(method):
    """The chapter's table: BC's Beta NLL; IBC uniform everywhere, argmax; DA-IBC from the expert's
    actions, a draw. (IBC ending with a draw is accepted too: the paper leaves its baseline's ending
    unstated.)"""
    if method == "bc":
        return {"loss": "beta nll", "negatives": None, "dfo_init": None, "dfo_select": None}
    if method == "ibc":
        return {"loss": "infonce", "negatives": "uniform", "dfo_init": "uniform", "dfo_select": "argmax"}
    return {
        "loss": "infonce",
        "negatives": "expert + noise",
        "dfo_init": "inverse-kde",
        "dfo_select": "sample",
    }


# =========================================================================== chapter 09: the replication
def ch09_bootstrap_difference(scores_a, scores_b, n_resamples, rng):
    """95 % percentile interval of mean(A) − mean(B) by the two-level bootstrap: for each method
    independently, A agents drawn with replacement, then E episodes of each drawn agent, averaged."""

    def resampled_means(x):  # (A, E) -> (n_resamples,)
        a, e = x.shape
        agents = rng.integers(a, size=(n_resamples, a))  # (R, A) the drawn agents
        episodes = rng.integers(e, size=(n_resamples, a, e))  # (R, A, E) their drawn episodes
        return x[agents[:, :, None], episodes].mean(axis=(1, 2))

    diffs = resampled_means(np.asarray(scores_a, float)) - resampled_means(np.asarray(scores_b, float))
    low, high = np.percentile(diffs, [2.5, 97.5])
    return float(low), float(high)


def ch09_exit_shares(visits, approach):
    """Share of the approach's visits that left by each exit (all three keys, summing to 1)."""

    turns = [v["turn"] for v in visits if v["approach"] == approach]
    return {t: turns.count(t) / len(turns) for t in ("left", "straight", "right")}


def ch09_verdict(estimate, low, high, threshold):
    """The interval decides, not the estimate: wholly above the threshold, wholly below, or neither
    (an end exactly on the threshold is neither)."""
    if low > threshold:
        return "holds"
    if high < threshold:
        return "does not hold"
    return "cannot tell at this scale"


# =========================================================================== chapter 10: road following
def ch10_swerve_rate(offsets, slight, clear):
    """Share of passes (P, T) whose farthest offset towards the side road, from where the pass began,
    reaches ``clear`` (a swerve, 1) or ``slight`` (half a swerve)."""
    x = np.asarray(offsets, dtype=float)
    peak = (x - x[:, :1]).max(axis=1)  # (P,) farthest towards the side road, from where the pass began
    return float(np.where(peak >= clear, 1.0, np.where(peak >= slight, 0.5, 0.0)).mean())


def ch10_command_whiteness(segments, dt):
    """W_cmd (eq. 2 of the steering-EBM paper) pooled over the stretches between restarts."""
    rates = np.concatenate([np.diff(np.asarray(s, dtype=float)) / dt for s in segments if len(s) >= 2])
    return float(np.sqrt(np.mean(rates**2)))


def ch10_crashes_per_km(runs):
    """Crashes over kilometres driven, summed over the runs."""
    return sum(r["crashes"] for r in runs) / (sum(r["distance_m"] for r in runs) / 1000.0)


# =========================================================================== chapter 11: route commands
def ch11_command(kind, distance_m, next_turn, connector_turn):
    """The command at a place: the route's turn within 20 m of a junction's entry, the connector's turn
    inside a junction, "follow" everywhere else (corners included)."""
    if kind == "junction connector":
        return connector_turn
    if kind == "approach" and distance_m <= 20.0:
        return next_turn
    return "follow"


def ch11_junction_success(rows):
    """Per command, crossings taken as commanded over crossings with it, pooled; None where there are none."""
    out = {}
    for command in ("left", "straight", "right", "all"):
        cs = [c for r in rows for c in r["crossings"] if command in ("all", c["command"])]
        out[command] = sum(c["taken"] == c["command"] for c in cs) / len(cs) if cs else None
    return out


def ch11_chance_crossings(exits):
    """Σ_k P(the first k exits are all right) = Σ_k Π_{j<=k} 1 / exits_j."""
    total, p = 0.0, 1.0
    for e in exits:
        p /= e
        total += p
    return total


# =========================================================================== chapter 12: the tree in the town
def ch12_fork(recorded, twin):
    """The first state at which the labels differ (either component, compared exactly) and
    |recorded steer - twin steer| there; a ValueError when they never differ."""
    differ = np.flatnonzero(np.any(recorded != twin, axis=1))  # (K,) the states whose labels differ
    if not len(differ):
        raise ValueError("the labels never differ: there is no fork")
    i = int(differ[0])
    return i, float(abs(recorded[i, 0] - twin[i, 0]))


def ch12_two_sided(steer, profile):
    """The book's valleys (within 3 nats of the minimum, a barrier of at least 1 nat): one left of straight
    (s < 0) and one right of it (s > 0)."""
    at = [v["steer"] for v in valleys(steer, profile)]
    return any(s < 0 for s in at) and any(s > 0 for s in at)


def ch12_exit_summary(counts):
    """The less taken exit's share of all the agents' stem crossings, and the agents that took both exits."""
    left = sum(c[0] for c in counts)
    right = sum(c[1] for c in counts)
    both = sum(c[0] > 0 and c[1] > 0 for c in counts)
    return {"minority": min(left, right) / (left + right), "both": both}


def ch13_euler_sample(velocity, y0, n_steps):
    """K Euler steps of dy/dt = v(y, t) from t = 0 to 1: y <- y + v(y, k / K) / K, nothing clipped."""
    y = y0
    for k in range(n_steps):
        y = y + velocity(y, k / n_steps) / n_steps
    return y


def ch13_flow_pair(y0, y1, t):
    """The straight path's point at t, y_t = (1 - t) y0 + t y1 (one t per row), and its velocity y1 - y0."""
    t = t[:, None]  # (N, 1)
    return (1 - t) * y0 + t * y1, y1 - y0


def ch13_ranking_logits(pos_energy, neg_energy, pos_log_q, neg_log_q):
    """Ranking NCE's logits, -E - log q for the expert (first) and the N counter-examples: (B, 1 + N)."""
    energy = torch.cat([pos_energy[:, None], neg_energy], dim=1)
    log_q = torch.cat([pos_log_q[:, None], neg_log_q], dim=1)
    return -energy - log_q


def ch12_commit(samples, previous_steer):
    """Of N sampled actions (B, N, 2), per row the one whose steering is nearest ``previous_steer`` (B,)."""
    gap = (samples[..., 0] - previous_steer[:, None]).abs()  # (B, N)
    return samples[torch.arange(len(samples)), gap.argmin(dim=1)]  # (B, 2): ties, the first


def ch12_head_passes(dfo_samples, dfo_iters, flow_samples, flow_steps):
    """Head evaluations per decision: DFO's N x N_iters energies, the flow's N x K velocities."""
    return dfo_samples * dfo_iters, flow_samples * flow_steps


def ch12_expert_log_q(candidates, actions, sigma):
    """log q(y) = log (1/M) Σ_m N(y; a_m, σ² I) at candidates (B, K, D), the expert actions (M, D)."""
    d = candidates.shape[-1]
    sq = (candidates[:, :, None, :] - actions[None, None, :, :]).square().sum(-1)  # (B, K, M)
    log_comp = -0.5 * sq / sigma**2 - 0.5 * d * math.log(2 * math.pi * sigma**2)  # (B, K, M)
    return torch.logsumexp(log_comp, dim=-1) - math.log(len(actions))  # (B, K)
