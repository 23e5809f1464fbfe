"""Named settings of the road-following study (chapter 10): ``laptop`` and ``tiny``.

The steering-EBM paper's study at a 2-core scale. Where a setting is the paper's, the field says
so; where it differs, it says why. ``differences(a, b)`` lists what two presets change.
"""

from __future__ import annotations

from dataclasses import dataclass

from ibc_tutorial.driving.bev import check_bev_size
from ibc_tutorial.experiments.settings import StoredSettings, config_from
from ibc_tutorial.experiments.settings import with_overrides as _with_overrides
from ibc_tutorial.training import TrainConfig
from ibc_tutorial.utils import check_choice, check_int, check_positive, check_probability

EVAL_TOWN = "town02"
"""The evaluation town, unseen in training."""
ROUTES = {
    "loop-ccw": ((0.0, 0.0), (196.0, 0.0), 5.0, ("straight",) * 4),
    "loop-cw": ((196.0, 0.0), (0.0, 0.0), 5.0, ("straight",) * 4),
    "y82-east": ((0.0, 82.0), (50.0, 82.0), 3.0, ("straight",) * 2),
    "y82-west": ((196.0, 82.0), (139.0, 82.0), 3.0, ("straight",) * 2),
}
"""name -> (from node, to node) of the start lane, start arc length (m), turns at the T-junctions."""

PAPER_BINS = 512
"""The paper's grid: 512 linearly spaced steering values (EBMs) and 512 bins (classification)."""
PAPER_TEMPERATURE_RAD2 = 2.5e-3
"""T of eq. 5 in the paper, with steering-wheel angles in radians."""
PAPER_STEER_RANGE_DEG = 250.0
"""Half the range of the paper's steering-wheel angles (its Fig. 4: "from ~-250 to ~250 degrees")."""


def book_temperature(
    t_rad2: float = PAPER_TEMPERATURE_RAD2, steer_range_deg: float = PAPER_STEER_RANGE_DEG
) -> float:
    """T of eq. 5 in the book's steering units ([-1, 1]), mapping the paper's range onto ours.

    A steering-wheel angle a (rad) is steer = a / A with A = 250° in radians; (a - a_GT)² / T is
    then (steer - steer_GT)² / (T / A²): T_book = 2.5e-3 / 4.363² = 1.31e-4, whose target keeps
    99.9 % of its mass within ±0.027 of the ground truth (the paper: "±5 degrees", ±0.02)."""
    import math

    a = math.radians(check_positive("steer_range_deg", steer_range_deg))
    return check_positive("t_rad2", t_rad2) / (a * a)


@dataclass(frozen=True)
class SteeringPreset(StoredSettings):
    """Everything ``ibc-tutorial replicate-steering`` needs: data, models, training, evaluation (stored flat:
    ``to_dict``, ``from_dict``)."""

    name: str
    """The preset's name."""
    # ---- data (town01, the expert)
    routes: int = 14
    """Expert routes driven in town01 for the demonstrations (14 x 2.5 min: 21,000 samples, the size
    of the DA-IBC paper's dataset and of the driving agents')."""
    route_minutes: float = 2.5
    """Duration of each route (minutes at 10 Hz: 1500 samples)."""
    collect_seed: int = 0
    """Seeds the routes, the side-road choices, the light phases and the steering noise."""
    side_road_share: float = 0.15
    """Where a road goes on past a side road, the share of passes that take the side road (the
    paper's data: side roads "rarely taken"); stems of a T (no straight exit) turn left or right
    with equal chance."""
    steer_noise: float = 0.3
    """The expert's steering perturbations during collection (as ``driving.collect``: the label
    stays the expert's own action; the perturbations show the model how to come back)."""
    speed: float = 6.0
    """The one target speed (m/s) of the longitudinal PID, in turns too, so speed tells nothing
    about the route (the expert's cruise speed)."""
    # ---- models
    bev_size: int = 64
    """Side of the BEV in pixels (the driving agents' laptop size)."""
    cnn_channels: tuple = (16, 32, 32, 64)
    """The BEV CNN's channels (the driving agents' laptop encoder)."""
    embed_dim: int = 128
    """Size of the BEV embedding and of the state (speed) embedding."""
    head_hidden: int = 32
    """Width of the energy head's hidden layers (it runs on all 513 candidates of every sample)."""
    head_layers: int = 2
    """Hidden layers of the energy head."""
    n_bins: int = PAPER_BINS
    """Steering values of the EBMs' grid and bins of the classifier (the paper: 512)."""
    mdn_components: int = 5
    """Gaussians of the MDN (the paper: 5)."""
    smoothing_alpha: float = 1.0
    """α of eq. 4, temporal smoothing (the paper: 1.0)."""
    soft_temperature: float = round(book_temperature(), 7)
    """T of eq. 5 in steering units: the paper's 2.5e-3 rad² mapped onto [-1, 1] (``book_temperature``)."""
    # ---- training
    steps: int = 3000
    """Adam steps per model (about 4.6 epochs of 21,000 samples). Trained 1500 steps, a regression
    crashed at all five right-angle right turns of town02's clockwise loop; 2500 steps more, at none."""
    batch_size: int = 32
    """Samples per minibatch (pairs of consecutive frames for temporal smoothing)."""
    lr: float = 1e-3
    """Adam step size (the paper: 1e-3)."""
    seeds: tuple = (0, 1, 2)
    """Training seeds (the paper: three runs per model)."""
    # ---- evaluation (town02)
    eval_routes: tuple = ("loop-ccw", "loop-cw", "y82-east", "y82-west")
    """The fixed town02 routes (``ROUTES``)."""
    route_cap_m: float = 0.0
    """Cut every route to this length (metres); 0 = the whole route."""
    eval_seed: int = 1000
    """Seeds the light phases of the evaluation routes."""

    def __post_init__(self):
        check_bev_size(self.bev_size)  # the renderer's rule: only the sizes it draws
        for f in (
            "routes",
            "embed_dim",
            "head_hidden",
            "head_layers",
            "mdn_components",
            "steps",
            "batch_size",
        ):
            check_int(f, getattr(self, f), minimum=1)
        check_int("n_bins", self.n_bins, minimum=2)
        for f in ("route_minutes", "speed", "lr", "soft_temperature"):
            check_positive(f, getattr(self, f))
        for f in ("steer_noise", "smoothing_alpha", "route_cap_m"):
            check_positive(f, getattr(self, f), allow_zero=True)
        check_probability("side_road_share", self.side_road_share)
        if not self.seeds or not self.eval_routes:
            raise ValueError("seeds and eval_routes must name at least one each")
        for r in self.eval_routes:
            check_choice("eval_routes", r, tuple(ROUTES))

    def train_config(self, seed: int, **extra) -> TrainConfig:
        """The ``TrainConfig`` of one model's run (``extra``: its other fields, e.g. ``log_every``)."""
        return config_from(TrainConfig, self, CONFIG_FIELDS, "train", seed=seed, **extra)


LAPTOP = SteeringPreset(name="laptop")
"""The chapter's study: 18 models trained and driven in about half an hour on 2 cores."""

TINY = SteeringPreset(
    name="tiny",
    routes=1,
    route_minutes=0.4,
    bev_size=32,
    cnn_channels=(4, 8),
    embed_dim=16,
    head_hidden=16,
    n_bins=32,
    mdn_components=2,
    steps=6,
    batch_size=8,
    seeds=(0,),
    eval_routes=("y82-west",),
    route_cap_m=70.0,
)
"""A seconds-long preset for the tests."""

PRESETS = {p.name: p for p in (LAPTOP, TINY)}
PURPOSES = {
    "laptop": "chapter 10's study: about 20 min on 2 cores (--workers 2 --threads 1)",
    "tiny": "a smoke test of the whole study: under a minute",
}
"""What each preset is for and how long its study takes (``replicate-steering --help``), from the shipped
folder's provenance, rounded up."""
"""All named presets."""


CONFIG_FIELDS = {
    "train.steps": "steps",
    "train.batch_size": "batch_size",
    "train.lr": "lr",
    "bev.size": "bev_size",
}
"""The library configs' names of a preset's fields (``training.TrainConfig``, the renderer's): what
``train_config`` builds its config from (``settings.config_from``), and names ``--set`` accepts beside the
fields' own."""


def with_overrides(preset: SteeringPreset, overrides) -> SteeringPreset:
    """``preset`` with the ``--set FIELD=VALUE`` overrides applied and checked (``experiments.settings``)."""
    return _with_overrides(preset, overrides, CONFIG_FIELDS)


def get_preset(name: str) -> SteeringPreset:
    """The preset called ``name`` ("laptop" or "tiny")."""
    return PRESETS[check_choice("preset", name, tuple(PRESETS))]


def differences(a: SteeringPreset, b: SteeringPreset) -> dict[str, tuple]:
    """Fields whose values differ: ``{field: (a's value, b's value)}`` (the name excluded)."""
    return a.differences(b)
