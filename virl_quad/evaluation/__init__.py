"""Evaluation: how well a policy imitates a reference motion, by the ground truth.

- :mod:`virl_quad.evaluation.score`    the ground-truth imitation score of a trajectory (pure numpy)
- :mod:`virl_quad.evaluation.rollout`  record episodes of a policy in the env and score them (``evaluate``)
- :mod:`virl_quad.evaluation.tracker`  the privileged reference tracker (a yardstick and a teacher)
"""
