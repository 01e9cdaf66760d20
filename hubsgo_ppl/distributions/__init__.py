"""Distributions of hubsgo-ppl: the pairwise binary MRF critic q(w; lambda) of Eq. 1."""

from .mrf import EXACT_LIMIT, PairwiseMRF, state_table

__all__ = ["PairwiseMRF", "state_table", "EXACT_LIMIT"]
