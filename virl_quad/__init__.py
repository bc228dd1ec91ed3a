"""virl_quad: quadrupeds that learn to move like a single video (VIRL), sim to real."""

__version__ = "0.1.0"
