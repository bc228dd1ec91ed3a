"""virl_quad: quadrupeds that learn to move like a single video (VIRL), sim to real."""

from virl_quad.quiet import import_pybullet_quietly as _import_pybullet_quietly

__version__ = "0.1.0"

_import_pybullet_quietly()  # its C-level banner would break the one-line error promise of the CLIs
