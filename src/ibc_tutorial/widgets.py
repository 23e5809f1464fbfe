"""ipywidgets explorers for the chapters, grouped by chapter.

Each explorer returns a widget to display in a cell that starts with ``# NBVAL_IGNORE_OUTPUT``;
the chapter shows a static figure of the same thing beside it (widget state is not stored).
Pictures are PNGs in an ``ipywidgets.Image`` (not an ``Output`` widget, whose captured output
the notebook executor cannot store without widget state).
"""

from __future__ import annotations

import io
from dataclasses import replace

import ipywidgets as w
import matplotlib.pyplot as plt
import numpy as np
import torch

from ibc_tutorial.optimizers.dfo import INITS, DFOConfig, DFOTrace, dfo_trace
from ibc_tutorial.optimizers.grid import grid_argmin
from ibc_tutorial.plotting import DPI
from ibc_tutorial.plotting.ingredients import draw_dfo_iteration
from ibc_tutorial.plotting.two_answers import plot_fork_profiles


def _png(fig) -> bytes:
    """The figure as PNG bytes (for an ``ipywidgets.Image``), then closed."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()


# =========================================================================== chapter 03: energy explorer
def energy_explorer(
    model,
    obs_fn,
    grid,
    *,
    values,
    value: float | None = None,
    description: str = "distance (m)",
    xlabel: str = "steering",
    title: str = "E(x, y) over actions",
):
    """A slider over an observation parameter that redraws the energy model's landscape over actions.

    The figure shows p(y | x) ∝ exp(−E(x, y)) over ``grid`` (top) and E itself (bottom), with the
    grid argmin (``optimizers.grid.grid_argmin``) marked. The static companion is
    ``plotting.plot_energy_curves``.

    Args:
        model: an ``EnergyModel`` (anything with ``embed`` and ``energy_from_embedding``).
        obs_fn: maps the slider's value to one observation (1, obs_dim).
        grid: (G, 1) candidate actions.
        values: (low, high, step) of the slider.
        value: its initial value (default: ``low``).
    """
    low, high, step = values
    slider = w.FloatSlider(
        value=low if value is None else value,
        min=low,
        max=high,
        step=step,
        description=description,
        continuous_update=False,
    )
    image = w.Image(format="png")
    a = grid[:, 0].numpy()  # (G,)

    def draw(*_):
        best_t, energies = grid_argmin(model, obs_fn(float(slider.value)), grid, return_energies=True)
        e = energies[0].numpy()  # (G,)
        p = np.exp(-(e - e.min()))
        p = p / (p.sum() * (a[1] - a[0]))
        best = float(best_t[0, 0])
        fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(6.0, 4.6), sharex=True)
        ax1.plot(a, p, color="C0")
        ax1.set_ylabel("p(y | x) ∝ exp(−E)")
        ax2.plot(a, e, color="C1")
        ax2.set_ylabel("E(x, y) (nats)")
        for ax in (ax1, ax2):
            ax.axvline(best, color="k", ls="--", lw=1, label=f"argmin {best:+.2f}")
        ax1.legend(fontsize=8)
        ax2.set_xlabel(xlabel)
        fig.suptitle(f"{title}: {description} = {float(slider.value):.1f}")
        fig.tight_layout()
        image.value = _png(fig)

    slider.observe(draw, names="value")
    draw()
    return w.VBox([slider, image])


# ========================================================================== chapter 06: DFO iteration stepper
def _dfo_iteration_figure(trace: DFOTrace, it: int, x: np.ndarray, e: np.ndarray, bins: int):
    """One iteration of a 1-D ``DFOTrace``, drawn by ``plotting.ingredients.draw_dfo_iteration``
    (the one implementation, shared with the static ``plot_dfo_iterations``), with axis labels."""
    fig, ax = plt.subplots(figsize=(6.0, 3.6))
    energy_ax = draw_dfo_iteration(ax, trace, it, x, e, bins)
    ax.set_ylabel("share of samples per bin")
    energy_ax.set_ylabel("energy E(x, y) (nats, red)", color="C3")
    fig.suptitle(f"DFO with init = {trace.config.init}, select = {trace.config.select}")
    fig.tight_layout()
    return fig


def dfo_stepper(
    energy_fn,
    grid,
    expert_actions,
    config: DFOConfig | None = None,
    *,
    seed: int = 0,
    bins: int = 60,
):
    """Step through Algorithm 1 (``optimizers.dfo.dfo_trace``) on a 1-D energy landscape.

    Controls: the iteration shown, the initialisation (``optimizers.dfo.INITS``), the final
    choice ("sample", "argmax") and the seed. Changing the initialisation, the choice or the seed
    re-runs DFO; the slider only moves through the stored populations. The static companion is
    ``plotting.plot_dfo_iterations``.

    Args:
        energy_fn: maps actions (N, 1) to energies (N,).
        grid: (G, 1) actions at which to draw the energy curve.
        expert_actions: (M, 1) the expert actions DFO initialises from.
        config: the DFO settings (``DFOConfig(n_samples=2000)`` if None); its ``init`` and
            ``select`` are the controls' initial values.
        seed: the initial seed of the run's generator.
        bins: histogram bins over the grid's range.
    """
    config = DFOConfig(n_samples=2000) if config is None else config
    x = grid[:, 0].numpy()  # (G,)
    e = energy_fn(grid).detach().numpy()  # (G,)
    iteration = w.IntSlider(value=1, min=1, max=config.n_iters, description="iteration")
    init = w.Dropdown(options=list(INITS), value=config.init, description="init")
    select = w.Dropdown(options=["sample", "argmax"], value=config.select, description="select")
    seed_box = w.IntText(value=seed, description="seed")
    image = w.Image(format="png")
    state = {}

    def run(*_):
        g = torch.Generator().manual_seed(int(seed_box.value))
        state["trace"] = dfo_trace(
            energy_fn, expert_actions, replace(config, init=init.value, select=select.value), generator=g
        )
        draw()

    def draw(*_):
        image.value = _png(_dfo_iteration_figure(state["trace"], int(iteration.value), x, e, bins))

    for control in (init, select, seed_box):
        control.observe(run, names="value")
    iteration.observe(draw, names="value")
    run()
    return w.VBox([w.HBox([iteration, init]), w.HBox([select, seed_box]), image])


# ========================================================================== chapter 11: figures by choice
def figure_explorer(draw, controls: dict):
    """The figure ``draw(**values)`` returns, redrawn whenever a control changes.

    ``controls``: ``{argument name of draw: ipywidgets control}`` (a ``Dropdown`` of routes, a
    ``SelectionSlider`` of distances, ...); their values are passed to ``draw`` by name. Chapter 11 uses it
    for its routes and for an agent's output under each command; each has a static figure beside it."""
    if not controls:
        raise ValueError("controls must hold at least one control")
    if not callable(draw):
        raise ValueError(f"draw must be a function returning a Figure, got {type(draw).__name__}")
    image = w.Image(format="png")

    def redraw(*_):
        image.value = _png(draw(**{name: c.value for name, c in controls.items()}))

    for control in controls.values():
        control.observe(redraw, names="value")
    redraw()
    return w.VBox([w.HBox(list(controls.values())), image])


# ========================================================================== chapter 12: the held-out forks
def fork_explorer(readings, names):
    """A slider over the held-out forks and a dropdown over the agents ``names`` ("all agents" or one):
    the chosen agents' energy over steering at the chosen fork, its two labels and the 3-nat depth marked
    (``plotting.two_answers.plot_fork_profiles``; the static companion is ``plot_profiles_at_forks``).

    ``readings``: ``experiments.agents.two_answers.analyse``'s ``readings.npz`` (or any mapping of its keys);
    ``names``: energy agents whose ``<name>/forks/profile`` it holds (``baseline/...`` included)."""
    names = [n for n in names if f"{n}/forks/profile" in readings]
    if not names:
        raise ValueError("names must hold at least one energy agent with forks/profile readings")
    forks = len(readings["states/forks/labels"])
    fork = w.IntSlider(value=0, min=0, max=forks - 1, description="fork", continuous_update=False)
    agent = w.Dropdown(options=["all agents", *names], value="all agents", description="agent")

    def draw(fork, agent):
        return plot_fork_profiles(readings, names if agent == "all agents" else [agent], int(fork))

    return figure_explorer(draw, {"fork": fork, "agent": agent})
