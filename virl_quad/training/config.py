"""Training options: one dataclass, one place for defaults, converted to rsl-rl's config dict.

Defaults are chosen for a 2-core CPU machine; ``--device cuda`` moves PPO and the
distance model to a GPU when there is one (the simulation stays on the CPU).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from virl_quad.cli import opt
from virl_quad.sim.params import DEFAULT_GROUND, GROUNDS

REWARDS = ("virl", "frame", "sequence", "no_ae", "gaifo", "oracle", "prior")
#: rewards that need no frames: the env's ground-truth score (oracle) or survival alone (prior)
FRAMELESS_REWARDS = ("oracle", "prior")
PRIOR_SOURCES = ("video", "motion")
#: where env workers run (the backends of virl_quad.envs.vec_env, which this module does not
#: import: it would load the simulator)
WORKER_KINDS = ("local", "ray")


@dataclass
class TrainArgs:
    """Options of ``python -m virl_quad.train``."""

    robot: str = opt("pupper", "robot to train (pupper or laikago)")
    demo: str = opt("trot", "demonstration: built-in gait name, .npz, motion file (.txt/.json) or video file")
    reward: str = opt("virl",
        "reward: virl (default), the paper's baselines frame/sequence/no_ae/gaifo, oracle (ground-truth "
        "pose reward, an upper bound) or prior (1 per step alive, no imitation: what the gait prior and "
        "warm start give alone)", choices=REWARDS)
    num_envs: int = opt(16, "parallel simulated robots")
    num_workers: int = opt(-1, "env workers (-1: one per CPU core of this machine; with --workers ray, set it to "
                                "the cluster's CPUs to use)")
    workers: str = opt("local",
        "where the env workers run: local (processes on this machine) or ray (Ray actors on the cluster "
        "at --ray-address; pip install -e \".[cluster]\")", choices=WORKER_KINDS)
    ray_address: str = opt("", "with --workers ray: the cluster to join (auto: the one `ray start` began "
                               "on this machine; host:port; empty: start a local one)")
    iterations: int = opt(1000,
        "PPO iterations the run ends at, in total: on --resume the ones already done count (an upper "
        "bound when --minutes is given)")
    minutes: float = opt(18.0,
        "wall-clock budget in minutes from the start of the command to the end of training (prior fit, "
        "warm start and PPO; 0: none, run all iterations); the final evaluation, export and video follow,"
        " so the default main job takes about 20 minutes on 2 cores")
    steps_per_env: int = opt(64, "env steps per env per iteration (rollout length)")
    seed: int = opt(0, "seed of envs, networks and sampling")
    device: str = opt("cpu", "torch device of PPO and the distance model (cpu or cuda)")
    run_dir: str = opt("", "output folder (empty: runs/<robot>-<reward>-<date>)")
    resume: str = opt("", "run folder to continue from its latest checkpoint")
    save_every: int = opt(10, "write a checkpoint every N iterations")
    eval_every: int = opt(25, "ground-truth evaluation every N iterations (0: only at the end)")
    eval_episodes: int = opt(2, "episodes per evaluation (fixed seeds)")
    eval_seconds: float = opt(10.0, "s, length of an evaluation episode")
    episode_seconds: float = opt(10.0, "s, training episode time limit")
    randomize: bool = opt(True, "domain randomisation during training")
    reward_updates: int = opt(2,
        "distance-model batch updates per iteration (M in Algorithm 1; <= 2 keeps reward cost <= 20 %)")
    reward_lr: float = opt(1e-3, "distance-model Adam learning rate")
    reward_wd: float = opt(-5.0, "w_d in r = exp(w_d * d^2) (paper: -5)")
    other_demos: str = opt("auto",
        "multi-task clips for the distance model (negatives of another class): \"auto\" = the other "
        "built-in gaits when --demo is one, \"none\", or comma-separated demo sources")
    ground: str = opt(DEFAULT_GROUND,
        "ground the camera sees in demonstration renders and agent frames: checker (forward progress "
        "visible to a person) or plain; the distance model paints either white "
        "(RewardConfig.paint_background)", choices=GROUNDS)
    reward_gp: float = opt(0.0,
        "gradient-penalty weight of the distance model: the squared gradient of a pair's distance with "
        "respect to its frames (AMP's stabiliser; 0: off, as in the paper)")
    adversarial_weight: float = opt(0.1,
        "sampling weight of expert-vs-agent negative pairs relative to each other pair kind (paper: 1): "
        "higher separates agent from expert sooner, until every agent behaviour gets reward 0; 0 leaves "
        "every behaviour rewarded alike")
    learning_rate: float = opt(3e-4,
        "PPO Adam learning rate at the start (then adaptive on a KL target of 0.01): a warm-started "
        "policy is kept close to where it starts")
    critic_learning_rate: float = opt(1e-3,
        "fixed Adam learning rate of the critic; the KL-adaptive rate is the actor's alone (at std 0.05 "
        "it sits at its 1e-5 floor, which would freeze a critic sharing it). 0: shared, as in rsl-rl")
    entropy_coef: float = opt(0.005, "PPO entropy bonus")
    init_std: float = opt(0.05,
        "initial action std in action units (x the action scale, 0.5 rad on Pupper: 0.025 rad per joint "
        "residual): rollouts stay close to the warm start that walks (motion_imitation fixes 0.125)")
    hidden: str = opt("256,128", "actor/critic MLP hidden sizes, comma separated")
    video: bool = opt(True, "write the final side-by-side video (demonstration | agent)")
    warm_start_rounds: int = opt(4,
        "with --tg: DAgger rounds that copy a tracker of the trajectory generator into the actor before "
        "PPO (0: start PPO from a fresh actor)")
    warm_start_steps: int = opt(4000, "control steps gathered per warm-start round")
    critic_warmup: int = opt(10,
        "iterations at the start of a run that fit the critic alone (actor frozen): PPO's first "
        "advantages come from a critic that knows the warm-started policy")
    symmetry: bool = opt(False,
        "rsl-rl symmetry augmentation: every PPO mini-batch also holds its left-right mirror (needs --tg:"
        " the mirror shifts the gait clock by the TG's leg offsets)")
    alignment_probe: bool = opt(True,
        "with a learned reward: at every evaluation, the rank correlation of the reward with the "
        "ground-truth score over a fixed graded set of rollouts (tracker variants, standing, other gaits,"
        " random; recorded once at the start), logged beside the score")
    prior_from: str = opt("video",
        "where the trajectory generator's parameters come from: video (fitted to the demonstration's "
        "frames by rendering candidate gaits and keeping the closest, the video alone) or motion (least "
        "squares on the demonstration's reference motion, else the built-in gait of its name)", choices=PRIOR_SOURCES)
    tg: bool = opt(True,
        "the policy acts as a residual on a trajectory generator (PMTG: 12 joint residuals + frequency "
        "and amplitude modulation; its parameters: see --prior-from); off: joint offsets from the default"
        " pose")


def validate(args: TrainArgs) -> None:
    """Raise ValueError (one line) for inconsistent options."""
    from virl_quad import robots

    robots.get(args.robot)
    if args.reward not in REWARDS:
        raise ValueError(f"unknown reward {args.reward!r}; choose one of: {', '.join(REWARDS)}")
    for name in ("warm_start_rounds", "critic_warmup"):
        if getattr(args, name) < 0:
            raise ValueError(f"--{name.replace('_', '-')} must be >= 0, got {getattr(args, name)}")
    if not 0 <= args.critic_learning_rate <= 1:
        raise ValueError(f"--critic-learning-rate must lie in [0, 1], got {args.critic_learning_rate}")
    if not 0 < args.init_std <= 2:
        raise ValueError(f"--init-std must lie in (0, 2] action units, got {args.init_std}")
    for name in ("num_envs", "iterations", "steps_per_env", "save_every", "warm_start_steps"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name.replace('_', '-')} must be >= 1")
    if args.reward_wd >= 0:
        raise ValueError(f"--reward-wd must be negative (r = exp(w_d d^2)), got {args.reward_wd}")
    if args.workers not in WORKER_KINDS:
        raise ValueError(f"unknown --workers {args.workers!r}; choose one of: {', '.join(WORKER_KINDS)}")
    if args.prior_from not in PRIOR_SOURCES:
        raise ValueError(f"unknown --prior-from {args.prior_from!r}; choose one of: {', '.join(PRIOR_SOURCES)}")
    if args.ground not in GROUNDS:
        raise ValueError(f"unknown --ground {args.ground!r}; choose one of: {', '.join(GROUNDS)}")
    if args.reward_gp < 0:
        raise ValueError(f"--reward-gp must be >= 0, got {args.reward_gp}")
    if args.adversarial_weight < 0:
        raise ValueError(f"--adversarial-weight must be >= 0, got {args.adversarial_weight}")
    if args.minutes < 0 or args.episode_seconds <= 0 or args.eval_seconds <= 0:
        raise ValueError("--minutes must be >= 0 and episode/eval seconds > 0")
    if args.symmetry and not args.tg:
        raise ValueError("--symmetry needs --tg (the mirror shifts the gait clock by the TG's leg offsets)")
    hidden_sizes(args)


def hidden_sizes(args: TrainArgs) -> list[int]:
    """Parse ``--hidden`` ("256,128") into layer sizes."""
    try:
        sizes = [int(s) for s in args.hidden.split(",") if s.strip()]
    except ValueError:
        raise ValueError(f"--hidden must be comma-separated integers, got {args.hidden!r}") from None
    if not sizes or min(sizes) < 1:
        raise ValueError(f"--hidden must list positive sizes, got {args.hidden!r}")
    return sizes


def rsl_rl_config(args: TrainArgs) -> dict:
    """The rsl-rl 5.x train config dict for these options."""
    hidden = hidden_sizes(args)
    model = {"class_name": "MLPModel", "hidden_dims": hidden, "activation": "elu"}
    return {
        "num_steps_per_env": args.steps_per_env,
        "save_interval": args.save_every,
        "check_for_nan": True,
        "obs_groups": {"actor": ["policy"], "critic": ["policy", "privileged"]},
        "actor": {**model, "obs_normalization": True,
                  "distribution_cfg": {"class_name": "GaussianDistribution", "init_std": args.init_std,
                                       "std_type": "scalar"}},
        "critic": {**model, "obs_normalization": True},
        "algorithm": {
            "class_name": "virl_quad.training.algorithm:VirlPPO",
            "num_learning_epochs": 5, "num_mini_batches": 4, "clip_param": 0.2,
            "gamma": 0.99, "lam": 0.95, "value_loss_coef": 1.0, "entropy_coef": args.entropy_coef,
            "learning_rate": args.learning_rate, "max_grad_norm": 1.0, "schedule": "adaptive",
            "desired_kl": 0.01, "use_clipped_value_loss": True,
            "critic_learning_rate": args.critic_learning_rate or None,
            "symmetry_cfg": {"use_data_augmentation": True,
                             "data_augmentation_func": "virl_quad.training.symmetry:augment"}
            if args.symmetry else None,
        },
    }


def to_dict(args: TrainArgs) -> dict:
    """Plain dict of the options (for checkpoints, report.json, metadata)."""
    return dataclasses.asdict(args)
