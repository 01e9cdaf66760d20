"""hubsgo-ppl: HUBS-GO, Bayesian sub-goal optimisation for hierarchical RL, with a Pyro MRF critic.

Layers (each imports only from the ones above it):
graph -> distributions -> infer -> validation -> specs -> envs -> agents -> experiments -> diagnostics -> cli
"""

__version__ = "0.1.0"
