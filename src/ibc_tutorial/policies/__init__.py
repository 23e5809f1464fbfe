"""Policies: observation encoders, explicit policies (chapter 02), the energy model and the flow-matching
policy."""

from ibc_tutorial.policies.encoders import BEVStateEncoder, MLPEncoder, ObservationEncoder

# the energy model (chapters 03-06)
from ibc_tutorial.policies.energy import EnergyModel, GridArgminPolicy, GridSamplePolicy

# explicit policies (chapter 02)
from ibc_tutorial.policies.explicit import (
    BetaPolicy,
    ClassifierPolicy,
    ExplicitPolicy,
    MDNPolicy,
    RegressionPolicy,
)

# the flow-matching policy
from ibc_tutorial.policies.flow import FlowConfig, FlowPolicy

__all__ = [
    "ObservationEncoder",
    "MLPEncoder",
    "BEVStateEncoder",
    # the energy model (chapters 03-06)
    "EnergyModel",
    "GridArgminPolicy",
    "GridSamplePolicy",
    # explicit policies (chapter 02)
    "ExplicitPolicy",
    "RegressionPolicy",
    "BetaPolicy",
    "ClassifierPolicy",
    "MDNPolicy",
    # the flow-matching policy
    "FlowConfig",
    "FlowPolicy",
]
