"""Named settings of the driving experiments: ``paper``, ``laptop`` and ``tiny``.

A ``Preset`` holds everything ``ibc-tutorial train``, ``evaluate`` and ``replicate`` need:
the network's size, the training settings of the DA-IBC paper's sec. 4.2, the inference
(Algorithm 1) settings, and the evaluation protocol of its Fig. 4.

**The three methods, as the DA-IBC paper defines them** (its secs. 2.4, 2.4.1, 2.5, 4.3, 5):

- ``bc``: the Beta policy of eq. 1 (its sec. 3.2 and [Antonelo et al. 2024]), acting with the
  Beta's mean (α, β > 0: see ``agent.BC_MIN_CONCENTRATION`` for why not α, β >= 1).
  Minibatches drawn with the inverse-KDE probabilities ("For BC, the loss function is
  weighted analogously", sec. 2.5).
- ``ibc``: "conventional IBC" [Florence et al. 2022]: InfoNCE (eq. 2) with counter-examples
  drawn uniformly from the action box, ỹ ~ U(y_min, y_max) (sec. 2.4), and the original DFO:
  initial samples uniform over the box, final action the lowest-energy sample (argmax of p̃).
  The paper's conclusion names exactly two changes that make DA-IBC out of IBC (the DFO
  initialisation and the counter-examples), so everything else, the KDE-weighted
  minibatches included (sec. 2.5: "to weigh the training samples in the BC and IBC losses"),
  is shared with DA-IBC.
- ``da-ibc``: InfoNCE with counter-examples copied from the minibatch's expert actions plus
  N(0, σ²I) (sec. 2.4 and its footnote 1), KDE-weighted minibatches (eq. 5 applied by
  sampling), and Algorithm 1: initial samples drawn from the expert actions with inverse-KDE
  weights (the text of sec. 2.4.1; chapter 06 explains why not the printed w ∝ KDE) and the
  final action *sampled*, ŷ ~ Categorical(p̃) (line 14).

**Two more families** (``FAMILY_METHODS``), trained on the same data with the same minibatches (KDE-weighted),
epochs, step size and head size, and driven in the same evaluations:

- ``flow``: the flow-matching policy (``policies.flow.FlowPolicy``: a velocity head v(z, y_t, t) on the Fig. 2
  embedding, conditional flow matching on straight paths from N(0, I) noise, Lipman et al. 2023 eq. 23). It
  acts by ``flow_steps`` Euler steps on ``flow_samples`` samples per decision and keeps the sample whose
  steering is nearest the previous steering (``agent.Agent``); no search, no energy.
- ``da-ibc-rnce``: DA-IBC with its InfoNCE replaced by ranking NCE (``losses.ranking_nce``: the logits
  subtract log q of the counter-examples' proposal, here the exact log-density of DA-IBC's expert sampler,
  ``negatives.ExpertSampler.log_prob``), so that exp(-E) learns p(y | x) itself rather than p / q; the same
  counter-examples and the same Algorithm 1 as ``da-ibc``.

The paper gives no σ for the counter-example noise; ``neg_sigma`` = 0.1 is the value chapter
04 studied.

**Made of the library's configs.** A preset is stored flat (checkpoints and results folders hold
``to_dict()``), and maps onto the configs of the library in one place, ``CONFIG_FIELDS``:
``collect_config()`` is the ``driving.collect.CollectConfig`` of its demonstrations,
``dfo_config(method)`` the ``optimizers.dfo.DFOConfig`` a method acts with, ``train_config(...)``
the ``training.TrainConfig`` of a run. ``__post_init__`` builds them, so every setting is validated
once, by the config that defines it, when the preset is made (before any work); ``bev_size`` by the
renderer's rule (``driving.bev.check_bev_size``: only the sizes it draws).

A variant is made with ``dataclasses.replace(LAPTOP, epochs=12)``, or from the command line with
``--set FIELD=VALUE`` (``with_overrides``: ``--set dfo.n_samples=1024`` or ``--set dfo_samples=1024``);
``differences(PAPER, p)`` lists what a preset changes from the paper.

**The lights.** The DA-IBC paper's BEV channels are binary maps, "values restricted to 0 or 1" (its
sec. 2.1), the light channels white where a light is red: the ``PAPER`` preset draws them so, as one
"must stop" bit (``light_encoding="flag"``: red and yellow at 1, green not drawn). The book's other
variant, "intensity" (red 1.0, yellow 0.6, green 0.3: chapter 07, which measured that it contradicts
none of the expert's labels), is chapter 08's ``intensity-lights`` ablation.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from ibc_tutorial.driving.bev import LIGHT_ENCODINGS, check_bev_size
from ibc_tutorial.driving.collect import CollectConfig
from ibc_tutorial.experiments.settings import StoredSettings, config_from
from ibc_tutorial.experiments.settings import with_overrides as _with_overrides
from ibc_tutorial.optimizers.dfo import DFOConfig
from ibc_tutorial.policies.flow import FlowConfig
from ibc_tutorial.policies.flow import network_evaluations as flow_network_evaluations
from ibc_tutorial.training import LR_SCHEDULES, TrainConfig
from ibc_tutorial.utils import check_choice, check_int, check_positive

LEGACY_LIGHT_ENCODING = "intensity"
"""How presets stored without a ``light_encoding`` field (written before it existed) drew the lights."""
METHODS = ("bc", "ibc", "da-ibc")
"""The three agents of the DA-IBC paper's sec. 4: Beta BC, conventional IBC and DA-IBC."""
FAMILY_METHODS = ("flow", "da-ibc-rnce")
"""Two more policy families on the same Fig. 2 encoder, data and training budget (chapter 12 reads them beside
the paper's three): the flow-matching policy and DA-IBC trained with ranking NCE (module docstring)."""
ALL_METHODS = METHODS + FAMILY_METHODS
"""Every method an agent can be trained with."""
DA_IBC_METHODS = ("da-ibc", "da-ibc-rnce")
"""The methods that act with DA-IBC's Algorithm 1 (inverse-KDE start, sampled final action) and draw DA-IBC's
counter-examples (expert actions plus noise)."""

CONFIG_FIELDS = {
    "collect.routes": "routes",
    "collect.seed": "collect_seed",
    "collect.min_minutes": "min_minutes",
    "collect.max_minutes": "max_minutes",
    "collect.brake_noise": "brake_noise",
    "collect.turn_hold_m": "turn_hold_m",
    "collect.stem_twins": "stem_twins",
    "bev.size": "bev_size",
    "bev.light_encoding": "light_encoding",
    "train.lr": "lr",
    "train.lr_schedule": "lr_schedule",
    "train.batch_size": "batch_size",
    "dfo.n_samples": "dfo_samples",
    "dfo.n_iters": "dfo_iters",
    "dfo.sigma_init": "dfo_sigma_init",
    "dfo.shrink": "dfo_shrink",
    "dfo.bandwidth": "kde_bandwidth",
}
"""The one map between the library configs' names (``CollectConfig``, the renderer's, ``TrainConfig``,
``DFOConfig``) and a preset's fields: what ``collect_config``, ``dfo_config`` and ``train_config`` build
those configs from (``settings.config_from``), and the names ``--set`` accepts beside the fields' own."""


@dataclass(frozen=True)
class Preset(StoredSettings):
    """One complete set of settings for training, evaluating and replicating (stored flat: ``to_dict``,
    ``from_dict``; a preset stored before ``light_encoding`` existed drew the lights by intensity,
    ``LEGACY_LIGHT_ENCODING``, whatever today's default)."""

    STORED_DEFAULTS = {"light_encoding": LEGACY_LIGHT_ENCODING}

    name: str
    """The preset's name."""
    # ---- data (the paper's sec. 4.1)
    routes: int = 10
    """Expert routes collected in town01 (the paper: 10, about 21,000 samples)."""
    collect_seed: int = 0
    """Seed of the collected routes."""
    min_minutes: float = 2.5
    """Shortest route in minutes (the paper: 2.5)."""
    max_minutes: float = 4.5
    """Longest route in minutes (mean 3.5, the paper's)."""
    brake_noise: float = 0.0
    """Strength of the expert's braking perturbations while collecting, in [0, 1] (the paper: none;
    ``driving.expert``)."""
    turn_hold_m: float = 0.0
    """The expert begins every turn this far before the junction entry, left and right alike (0: as its
    steering target enters the turn's arc, so right turns begin earlier; ``driving.expert``; the paper does
    not say how its expert times its turns)."""
    stem_twins: int = 0
    """Twin pairs per town01 stem added to the routes: each pair crosses one stem left and right from the
    identical state (``driving.collect``), so that the stem is a state with two answers, as the tree is (0:
    none, the paper's data)."""
    # ---- network (the paper's Fig. 2)
    bev_size: int = 192
    """Side of the bird's-eye view in pixels (the paper: 192)."""
    light_encoding: str = "flag"
    """How the BEV draws lights (``driving.bev.LIGHT_ENCODINGS``): as one "must stop" bit ("flag", the paper's
    binary channels: red and yellow 1, green not drawn) or by state ("intensity": red 1.0, yellow 0.6, green
    0.3, the book's variant)."""
    cnn_channels: tuple = (32, 64, 128, 256)
    """Output channels of the CNN's stride-2 convolutions."""
    embed_dim: int = 256
    """Size of the BEV embedding and of the state embedding (the paper: 256 each)."""
    head_hidden: int = 256
    """Width of the heads' hidden layers (the energy head's fused layer included)."""
    head_layers: int = 2
    """Hidden layers of the energy head (the first is the factorised fused layer)."""
    # ---- training (the paper's sec. 4.2)
    lr: float = 1e-5
    """Adam step size (the paper: 1e-5)."""
    lr_schedule: str = "constant"
    """"constant" (the paper: no schedule given) or "cosine" decay to 0 over the run
    (``training.TrainConfig``)."""
    epochs: int = 400
    """Training epochs, each ceil(M / batch_size) minibatches (the paper: up to 400)."""
    batch_size: int = 128
    """Minibatch size (the paper: 128)."""
    n_neg: int = 1024
    """Counter-examples per sample, N_neg (the paper: 1024)."""
    neg_sigma: float = 0.1
    """σ of the DA-IBC counter-examples' noise N(0, σ²I) (not given in the paper; chapter 04's value)."""
    kde_bandwidth: float = 0.2
    """KDE bandwidth h for the minibatch weights and the DFO initialisation (the paper: 0.2)."""
    # ---- inference (Algorithm 1, the paper's sec. 4.2)
    dfo_samples: int = 16384
    """N_samples of Algorithm 1 (the paper: 16,384)."""
    dfo_iters: int = 5
    """N_iters of Algorithm 1 (the paper: 5)."""
    dfo_sigma_init: float = 0.5
    """σ_init of Algorithm 1 (the paper: 0.5)."""
    dfo_shrink: float = 0.5
    """K, the shrink factor of Algorithm 1 (the paper: 0.5)."""
    # ---- the flow policy's inference (``flow`` agents only)
    flow_steps: int = 4
    """K, the flow policy's Euler steps per decision (``policies.flow.FlowConfig.n_steps``)."""
    flow_samples: int = 16
    """N, the flow policy's samples per decision, drawn in one batch (``FlowConfig.n_samples``): N x K = 64
    head evaluations, 1/24 of the laptop preset's DFO (512 x 3)."""
    # ---- evaluation (the paper's Fig. 4)
    eval_every: int = 10
    """Closed-loop evaluation in town02 every this many epochs (the paper: 10)."""
    eval_episodes: int = 10
    """Episodes of each evaluation during training (the paper: 10)."""
    eval_steps: int = 3000
    """Steps of each episode during training (the paper: 3000 = 300 s)."""
    final_episodes: int = 10
    """Episodes of the final evaluation of each agent (the paper's table: 10)."""
    final_steps: int = 3000
    """Steps of each final episode (the paper: 3000)."""
    heldout_episodes: int = 10
    """Episodes of a second final evaluation from other starts (``evaluate.HELDOUT_SEED``), which nothing is
    tuned on
    (0: none)."""
    seeds: tuple = (0, 1, 2)
    """Training seeds: one agent per seed and method (the paper: three agents per method)."""
    methods: tuple = METHODS
    """The methods a replication trains (all three; an ablation may train fewer)."""
    routeless_episodes: int = 3
    """Free-driving episodes per agent for the Fig. 5 analogue (BC and DA-IBC); 0: no Fig. 5/6 analogues."""
    routeless_steps: int = 3000
    """Steps of each free-driving episode."""
    commands: bool = False
    """True: the agents take a route command (CIL's four, ``driving.commands``) one-hot through the state
    MLP, are trained on the demonstrations' commands and evaluated on the town02 routes
    (``driving.route_following``; chapter 11). False: routeless, the DA-IBC paper's agents (a preset stored
    before this field existed is routeless)."""
    balanced_routes: bool = False
    """True: the town01 demonstration routes are chosen so that every route command, "straight" included,
    is commanded about equally often (``driving.command_balance.balanced_routes``: at each junction the
    legal exit commanded least so far); False: random routes, on which "straight" is commanded about half
    as often as each turn (a preset stored before this field existed has random routes)."""
    command_branches: bool = False
    """With ``commands``: True, the command also chooses one of four branch layers on the joint embedding
    (CIL's branched network, ``policies.BEVStateEncoder``); False, the command is only an input of the state
    MLP (CIL's command-input network; a preset stored before this field existed)."""
    route_episodes: int = 1
    """With ``commands``: drives of every town02 route in the final evaluation (light phases seeded apart)."""
    route_max_steps: int = 0
    """With ``commands``: cap on the steps of every route drive of the final evaluation (0: none, each route's
    own budget, ``driving.route_following.MIN_MEAN_SPEED``)."""

    def __post_init__(self):
        # the settings of the library's configs are checked by those configs (CONFIG_FIELDS)
        self.collect_config()
        for method in ("ibc", "da-ibc"):
            self.dfo_config(method)
        check_int("flow_steps", self.flow_steps, minimum=1)
        check_int("flow_samples", self.flow_samples, minimum=1)
        self.flow_config()
        check_bev_size(self.bev_size)  # the renderer's rule: only the sizes it draws
        check_choice("light_encoding", self.light_encoding, LIGHT_ENCODINGS)
        check_choice("lr_schedule", self.lr_schedule, LR_SCHEDULES)
        check_positive("lr", self.lr)
        for f in (
            "embed_dim",
            "head_hidden",
            "head_layers",
            "epochs",
            "batch_size",
            "n_neg",
            "eval_every",
            "eval_episodes",
            "eval_steps",
            "final_episodes",
            "final_steps",
            "routeless_steps",
            "flow_steps",
            "flow_samples",
        ):
            check_int(f, getattr(self, f), minimum=1)
        for f in ("commands", "balanced_routes", "command_branches"):
            if not isinstance(getattr(self, f), bool):
                raise ValueError(f"{f} must be True or False, got {getattr(self, f)!r}")
        if self.command_branches and not self.commands:
            raise ValueError("command_branches=True needs commands=True: a routeless agent has no command")
        check_int("route_episodes", self.route_episodes, minimum=1)
        check_int("route_max_steps", self.route_max_steps, minimum=0)
        for f in ("routeless_episodes", "heldout_episodes"):
            check_int(f, getattr(self, f), minimum=0)
        if (
            not self.methods
            or any(m not in ALL_METHODS for m in self.methods)
            or len(set(self.methods)) < len(self.methods)
        ):
            raise ValueError(f"methods must name distinct methods of {ALL_METHODS}, got {self.methods!r}")
        check_positive("neg_sigma", self.neg_sigma, allow_zero=True)
        if not self.cnn_channels or any(int(c) < 1 for c in self.cnn_channels):
            raise ValueError(f"cnn_channels must be positive integers, got {self.cnn_channels!r}")
        if not self.seeds:
            raise ValueError("seeds must name at least one seed")

    # ---- the library's configs (CONFIG_FIELDS says which field goes where)
    def collect_config(self) -> CollectConfig:
        """The demonstrations' ``CollectConfig``: town01 routes (the paper's sec. 4.1)."""
        return config_from(CollectConfig, self, CONFIG_FIELDS, "collect", town="town01")

    def dfo_config(self, method: str) -> DFOConfig | None:
        """How ``method`` runs Algorithm 1 (None for bc and flow, which do not search): the original IBC's
        DFO, or DA-IBC's (module docstring; da-ibc-rnce acts as da-ibc)."""
        check_choice("method", method, ALL_METHODS)
        if method in ("bc", "flow"):
            return None
        if method == "ibc":
            init, select = "uniform", "argmax"  # the original IBC's DFO: uniform start, lowest energy
        else:
            init, select = (
                "inverse-kde",
                "sample",
            )  # Algorithm 1: w ∝ 1 / ĝ start, ŷ ~ Categorical(p̃) (line 14)
        return config_from(DFOConfig, self, CONFIG_FIELDS, "dfo", init=init, select=select)

    def flow_config(self) -> FlowConfig:
        """The ``FlowConfig`` a ``flow`` agent acts with: ``flow_steps`` Euler steps on ``flow_samples``
        samples, N(0, I) noise, the action box [-1, 1]²."""
        return FlowConfig(n_steps=self.flow_steps, n_samples=self.flow_samples)

    def network_evaluations(self, method: str) -> dict[str, int]:
        """What one decision of a ``method`` agent costs per observation: encoder passes and head passes
        (DFO: N_samples x N_iters energy evaluations; flow: N x K velocity evaluations; bc: one Beta head)."""
        check_choice("method", method, ALL_METHODS)
        if method == "bc":
            return {"encoder": 1, "head": 1}
        if method == "flow":
            return flow_network_evaluations(self.flow_samples, self.flow_steps)
        return {"encoder": 1, "head": self.dfo_samples * self.dfo_iters}  # Algorithm 1: N x N_iters

    def train_config(self, steps_per_epoch: int, seed: int, **extra) -> TrainConfig:
        """The ``TrainConfig`` of a run: ``epochs`` x ``steps_per_epoch`` Adam steps, a callback (evaluation
        and checkpoint) every ``eval_every`` epochs; ``extra``: its other fields (``progress``, ``desc``)."""
        return config_from(
            TrainConfig,
            self,
            CONFIG_FIELDS,
            "train",
            steps=self.epochs * steps_per_epoch,
            seed=seed,
            log_every=self.eval_every * steps_per_epoch,
            **extra,
        )


PAPER_UNSTATED = frozenset(
    {"lr_schedule", "brake_noise", "turn_hold_m", "neg_sigma", "heldout_episodes", "routeless_episodes"}
)
"""Fields of ``PAPER`` whose value the DA-IBC paper does not state, the book's assumption: no schedule
is given (constant assumed), no braking perturbations or turn timing of its expert, no σ for the
counter-examples' noise, no held-out evaluation (the book's own check), and its Fig. 5 is one 3,000 s
drive per agent rather than episodes (``routeless_episodes=3`` is the book's reading)."""

PAPER = Preset(name="paper")
"""The DA-IBC paper's settings (sec. 4.2), its binary light channels included. Days of compute on a CPU;
given for reference."""

LAPTOP = Preset(
    name="laptop",
    routes=20,  # twice the paper's 10: more stems seen taken both ways; higher scores (chapter 08)
    brake_noise=1.0,  # held brakes while collecting: the data show the car leaving from rest (chapter 08)
    bev_size=64,  # 9x fewer pixels than 192; the same 5 channels and field of view (OR-pooled)
    light_encoding="flag",  # the paper's one bit; against intensities, chapter 08 cannot tell them apart
    cnn_channels=(16, 32, 32, 64),  # a small CNN: 64 -> 4 x 4 x 64 after four stride-2 convolutions
    embed_dim=256,  # as the paper: 256-d BEV and 256-d state embeddings
    head_hidden=128,  # the energy head runs N_neg times per sample and N_samples times per decision
    head_layers=2,
    lr=1e-3,  # 100x the paper's 1e-5, for 4 epochs instead of up to 400
    lr_schedule="cosine",  # decays to 0 over the 4 epochs, so the last epochs settle rather than jump
    epochs=4,  # over twice the paper's data: the gradient steps of 8 epochs over 10 routes
    batch_size=128,  # as the paper
    n_neg=128,  # 1/8 of the paper's 1024
    dfo_samples=512,  # 1/32 of the paper's 16,384
    dfo_iters=3,  # the paper: 5
    eval_every=2,  # the paper: every 10 of up to 400 epochs; here every 2 of 4
    eval_episodes=4,  # during training only (the paper: 10); the final table uses final_episodes
    eval_steps=600,  # 60 s episodes during training (the paper: 300 s)
    final_episodes=10,  # as the paper
    final_steps=3000,  # as the paper: 300 s
    heldout_episodes=5,  # a check on other starts, half the table's episodes
    seeds=(0, 1, 2, 3, 4, 5, 6),  # seven agents per method, what the hour holds (the paper: three)
    routeless_episodes=10,  # enough junction passes to count exits per junction
    routeless_steps=3000,
)
"""What a 2-core CPU can replicate in under an hour (``ibc-tutorial replicate --preset laptop``)."""

TWO_ANSWERS = replace(
    LAPTOP,
    name="two-answers",
    routes=6,  # the laptop preset's driving, on 6 routes ...
    stem_twins=20,  # ... and 20 twin pairs per town01 stem: each stem crossed 20 times each way, at one state
    turn_hold_m=2.0,  # a driver who turns the wheel at one point: a label gap of about 0.4 at the fork
    epochs=3,  # about 54,000 samples: 3 epochs are the laptop preset's number of gradient steps
    eval_every=3,  # one evaluation during training, at its end
    seeds=(0, 1, 2, 3, 4),  # five agents per method
)
"""Demonstrations designed so that the stem of a T is a state with two answers (``ibc-tutorial replicate
--preset two-answers``, chapter 12): the laptop preset's settings, fewer routes, and stem twins recorded
with an expert that begins each turn 2 m before the junction entry."""

TEN_ROUTES = replace(
    LAPTOP,
    name="ten-routes",
    routes=10,  # the paper's 10 routes
    epochs=8,
    seeds=(0, 1, 2, 3, 4),
)
"""The laptop preset with the paper's 10 demonstration routes and 8 epochs (as many gradient steps),
five agents per method: ``laptop`` with ``--set collect.routes=10 --set epochs=8 --set seeds=0,1,2,3,4``.
Its replication (``book/results/ten-routes``) is a row of chapter 08's table of departures and the base
of two more (the epochs alone, the expert's turns begun together); chapter 12 reads its agents at the
stems of the T-junctions as one of five changes."""

TINY = Preset(
    name="tiny",
    routes=1,
    min_minutes=0.15,
    max_minutes=0.2,
    brake_noise=1.0,  # the laptop preset's data and lights, in miniature
    bev_size=32,
    light_encoding="flag",
    cnn_channels=(4, 8),
    embed_dim=16,
    head_hidden=16,
    head_layers=2,
    lr=1e-3,
    epochs=2,
    batch_size=32,
    n_neg=8,
    dfo_samples=32,
    dfo_iters=2,
    eval_every=1,
    eval_episodes=2,
    eval_steps=10,
    final_episodes=2,
    final_steps=15,
    heldout_episodes=1,
    seeds=(0,),
    routeless_episodes=1,
    routeless_steps=20,
    route_max_steps=20,  # with --commands: the routes' first 2 s
)
"""A seconds-long preset for the tests and the chapters' live demonstrations."""

PRESETS = {p.name: p for p in (PAPER, LAPTOP, TEN_ROUTES, TWO_ANSWERS, TINY)}
PURPOSES = {
    "paper": "the DA-IBC paper's settings (sec. 4.2), for reference: days of compute on a CPU",
    "laptop": "chapters 08-09's replication: about 60 min on 2 cores (--workers 2 --threads 1)",
    "ten-routes": "the paper's 10 routes, 8 epochs, 5 agents per method: about 40 min on 2 cores",
    "two-answers": "chapter 12's study (stem twins): about 55 min on 2 cores",
    "tiny": "a smoke test of the whole pipeline: under a minute",
}
"""What each preset is for and how long its replication takes (``replicate --help``): the wall times of
the shipped folders' provenance, rounded up."""
"""All named presets."""


def get_preset(name: str) -> Preset:
    """The preset called ``name`` (one of ``PRESETS``)."""
    return PRESETS[check_choice("preset", name, tuple(PRESETS))]


def with_overrides(preset: Preset, overrides) -> Preset:
    """``preset`` with the ``--set FIELD=VALUE`` overrides applied and checked (``experiments.settings``)."""
    return _with_overrides(preset, overrides, CONFIG_FIELDS)


def differences(a: Preset, b: Preset) -> dict[str, tuple]:
    """Fields whose values differ: ``{field: (a's value, b's value)}`` (the name excluded). Compared with
    ``PAPER``, a value the paper does not state (``PAPER_UNSTATED``) is given as "<value> (not stated)"."""

    def shown(p: Preset, k: str, value):
        return f"{value} (not stated)" if p == PAPER and k in PAPER_UNSTATED else value

    return {k: (shown(a, k, va), shown(b, k, vb)) for k, (va, vb) in a.differences(b).items()}
