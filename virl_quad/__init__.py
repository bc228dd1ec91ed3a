"""virl_quad: quadrupeds that learn to move like a single video (VIRL), sim to real.

Importing the package loads no simulator: PyBullet is imported (quietly, see
:mod:`virl_quad.quiet`) by the modules that use it, so the robot-side policy server
(:mod:`virl_quad.deploy.serve`, :mod:`virl_quad.policy`) runs without it.
"""

__version__ = "0.1.0"
