"""Reference motions: what a robot should do, as keyframes of root pose and joint angles.

- :mod:`virl_quad.motion.state`      ``MotionState`` (one instant) and ``MotionLike`` (what the env uses)
- :mod:`virl_quad.motion.motion`     ``Motion``: keyframes played back at any time (loops, heading)
- :mod:`virl_quad.motion.motion_io`  motion files: motion_imitation / DeepMimic clips, the Laikago recording
- :mod:`virl_quad.motion.gaits`      built-in gaits (trot, pace, bound, pronk, walk) by IK
- :mod:`virl_quad.motion.retarget`   one robot's motion played on another by its feet
- :mod:`virl_quad.motion.contacts`   ground-contact check of clips (``python -m virl_quad.demo contacts``)

Importing this package loads numpy only.
"""

from virl_quad.motion.state import MotionLike, MotionState

__all__ = ["MotionLike", "MotionState"]
