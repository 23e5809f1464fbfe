"""ipywidgets explorers for the chapters, grouped by chapter.

Each explorer returns a widget to display in a cell that starts with ``# NBVAL_IGNORE_OUTPUT``;
the chapter shows a static figure of the same thing beside it (widget state is not stored).
Figures are drawn with ``ibc_tutorial.plotting`` and shown as PNG inside an ``Output`` widget.
"""

from __future__ import annotations


# =========================================================================== chapter 03: energy explorer
def energy_explorer(model, obs_fn, grid, *, values, value: float | None = None, description: str = "distance (m)", xlabel: str = "steering", title: str = "E(x, y) over actions"):
    """A slider over an observation parameter that redraws the energy model's landscape over actions.

    The figure shows p(y | x) ∝ exp(−E(x, y)) over ``grid`` (top) and E itself (bottom), with the
    grid argmin marked. The static companion is ``plotting.plot_energy_curves``. The picture is a
    PNG in an ``Image`` widget (not an ``Output`` widget, whose captured output the notebook
    executor cannot store without widget state).

    Args:
        model: an ``EnergyModel`` (anything with ``energy(obs, actions)``).
        obs_fn: maps the slider's value to one observation (1, obs_dim).
        grid: (G, 1) candidate actions.
        values: (low, high, step) of the slider.
        value: its initial value (default: ``low``).
    """
    import io

    import ipywidgets as w
    import matplotlib.pyplot as plt
    import numpy as np
    import torch

    from ibc_tutorial.plotting import DPI

    low, high, step = values
    slider = w.FloatSlider(value=low if value is None else value, min=low, max=high, step=step, description=description, continuous_update=False)
    image = w.Image(format="png")
    a = grid[:, 0].numpy()

    def draw(*_):
        with torch.no_grad():
            e = model.energy(obs_fn(float(slider.value)), grid)[0].numpy()  # (G,)
        p = np.exp(-(e - e.min()))
        p = p / (p.sum() * (a[1] - a[0]))
        best = a[int(e.argmin())]
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
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=DPI)
        plt.close(fig)
        image.value = buf.getvalue()

    slider.observe(draw, names="value")
    draw()
    return w.VBox([slider, image])


# =========================================================================== chapter 06: DFO iteration stepper
def _png(fig) -> bytes:
    """The figure as PNG bytes (for an ``ipywidgets.Image``), then closed."""
    import io

    import matplotlib.pyplot as plt

    from ibc_tutorial.plotting import DPI

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()


def dfo_stepper(energy_fn, grid, expert_actions, *, n_samples: int = 2000, n_iters: int = 5, seed: int = 0, bins: int = 60, **dfo_kwargs):
    """Step through Algorithm 1 (``inference.dfo_trace``) on a 1-D energy landscape.

    Controls: the iteration shown, the initialisation ("inverse-kde", "kde", "uniform"), the final
    choice ("sample", "argmax") and the seed. Changing the initialisation, the choice or the seed
    re-runs DFO; the slider only moves through the stored populations. The picture is an
    ``ipywidgets.Image`` (no ``Output`` widget, so executing the notebook stores nothing of it).

    Args:
        energy_fn: maps actions (N, 1) to energies (N,).
        grid: (G, 1) actions at which to draw the energy curve.
        expert_actions: (M, 1) the expert actions DFO initialises from.
        n_samples, n_iters, seed, dfo_kwargs: passed to ``dfo_trace``.
    """
    import ipywidgets as w
    import matplotlib.pyplot as plt
    import torch

    from ibc_tutorial.inference import dfo_trace
    from ibc_tutorial.plotting import _draw_dfo_iteration

    x = grid[:, 0].numpy()
    e = energy_fn(grid).detach().numpy()
    iteration = w.IntSlider(value=1, min=1, max=n_iters, description="iteration")
    init = w.Dropdown(options=["inverse-kde", "kde", "uniform"], value=dfo_kwargs.pop("init", "inverse-kde"), description="init")
    select = w.Dropdown(options=["sample", "argmax"], value=dfo_kwargs.pop("select", "sample"), description="select")
    seed_box = w.IntText(value=seed, description="seed")
    image = w.Image(format="png")
    state = {}

    def run(*_):
        g = torch.Generator().manual_seed(int(seed_box.value))
        state["trace"] = dfo_trace(energy_fn, expert_actions, n_samples=n_samples, n_iters=n_iters, init=init.value, select=select.value, generator=g, **dfo_kwargs)
        draw()

    def draw(*_):
        fig, ax = plt.subplots(figsize=(6.0, 3.6))
        _draw_dfo_iteration(ax, state["trace"], int(iteration.value), x, e, bins)
        ax.set_ylabel("share of samples per bin")
        fig.suptitle(f"DFO with init = {init.value}, select = {select.value}")
        fig.tight_layout()
        image.value = _png(fig)

    for control in (init, select, seed_box):
        control.observe(run, names="value")
    iteration.observe(draw, names="value")
    run()
    return w.VBox([w.HBox([iteration, init]), w.HBox([select, seed_box]), image])
