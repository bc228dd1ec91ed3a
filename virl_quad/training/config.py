"""Training options: one dataclass of sections (one per concern), one place for defaults,
converted to rsl-rl's config dict.

Defaults are chosen for a 2-core CPU machine; ``--device cuda`` moves PPO and the
distance model to a GPU when there is one (the simulation stays on the CPU).
"""

from __future__ import annotations

from dataclasses import dataclass

from virl_quad.cli import Sectioned, from_options, opt, options
from virl_quad.sim.params import DEFAULT_GROUND, GROUNDS

REWARDS = ("virl", "frame", "sequence", "no_ae", "gaifo", "oracle", "prior")
#: rewards that need no frames: the env's ground-truth score (oracle) or survival alone (prior)
FRAMELESS_REWARDS = ("oracle", "prior")
PRIOR_SOURCES = ("video", "motion")
#: where env workers run (the backends of virl_quad.envs.vec_env, which this module does not
#: import: it would load the simulator)
WORKER_KINDS = ("local", "ray")


@dataclass
class RunOptions:
    """What to train, for how long, and where the results go."""

    robot: str = opt("pupper", "robot to train (pupper or laikago)")
    demo: str = opt("trot", "demonstration: built-in gait name, .npz, motion file (.txt/.json) or video file")
    reward: str = opt("virl",
        "reward: virl (default), the paper's baselines frame/sequence/no_ae/gaifo, oracle (ground-truth "
        "pose reward, an upper bound) or prior (1 per step alive, no imitation: what the gait prior and "
        "warm start give alone)", choices=REWARDS)
    oracle_speed_weight: float = opt(0.3,
        "with --reward oracle: share of the reward paid for matching the reference's forward speed, "
        "exp(-(dv / 0.2 m/s)^2); the rest is the ground-truth score, whose own speed term barely tells "
        "a gait drifting backwards from one walking forwards (0: the score alone)")
    minutes: float = opt(18.0,
        "wall-clock budget in minutes from the start of the command to the end of training (prior fit, "
        "warm start and PPO; 0: none, run all iterations); the final evaluation, export and video follow,"
        " so the default main job takes about 20 minutes on 2 cores")
    iterations: int = opt(1000,
        "PPO iterations the run ends at, in total: on --resume the ones already done count (an upper "
        "bound when --minutes is given)")
    seed: int = opt(0, "seed of envs, networks and sampling")
    device: str = opt("cpu", "torch device of PPO and the distance model (cpu or cuda)")
    run_dir: str = opt("", "output folder (empty: runs/<robot>-<reward>-<date>)")
    resume: str = opt("", "run folder to continue from its latest checkpoint")
    save_every: int = opt(10, "write a checkpoint every N iterations")
    video: bool = opt(True, "write the final side-by-side video (demonstration | agent)")


@dataclass
class EnvOptions:
    """The simulated robots and where they run."""

    num_envs: int = opt(16, "parallel simulated robots")
    num_workers: int = opt(-1, "env workers, and the video fit's render processes (-1: one per CPU core of this "
                                "machine; with --workers ray, set it to the cluster's CPUs to use)")
    workers: str = opt("local",
        "where the env workers run: local (processes on this machine) or ray (Ray actors on the cluster "
        "at --ray-address; pip install -e \".[cluster]\")", choices=WORKER_KINDS)
    ray_address: str = opt("", "with --workers ray: the cluster to join (auto: the one `ray start` began "
                               "on this machine; host:port; empty: start a local one)")
    episode_seconds: float = opt(10.0, "s, training episode time limit")
    randomize: bool = opt(True, "domain randomisation during training")
    ground: str = opt(DEFAULT_GROUND,
        "ground the camera sees in demonstration renders and agent frames: checker (forward progress "
        "visible to a person) or plain; the distance model paints either white "
        "(RewardConfig.pairs.paint_background)", choices=GROUNDS)


@dataclass
class PriorOptions:
    """The gait prior and the warm start."""

    tg: bool = opt(True,
        "the policy acts as a residual on a trajectory generator (PMTG: 12 joint residuals + frequency "
        "and amplitude modulation; its parameters: see --prior-from); off: joint offsets from the default"
        " pose")
    prior_from: str = opt("video",
        "where the trajectory generator's parameters come from: video (fitted to the demonstration's "
        "frames by rendering candidate gaits and keeping the closest, the video alone) or motion "
        "(least squares on the demonstration's reference motion, else the built-in gait of its name)",
        choices=PRIOR_SOURCES)
    warm_start_rounds: int = opt(4,
        "with --tg: DAgger rounds that copy a tracker of the trajectory generator into the actor before "
        "PPO (0: start PPO from a fresh actor, and the video fit's finalists get no physics check)")
    warm_start_steps: int = opt(4000, "control steps gathered per warm-start round, and per finalist in the "
                                "physics check of the video fit (its tracker on the physics robot)")


@dataclass
class DistanceOptions:
    """The learned reward: VIRL's distance model, trained beside the policy."""

    reward_updates: int = opt(2,
        "distance-model batch updates per iteration (M in Algorithm 1; <= 2 keeps reward cost <= 20 %)")
    reward_pretrain: int = opt(200,
        "distance-model batch updates before the policy trains (a new run only), on the demonstration's "
        "own pairs, the other clips and one rollout of the warm-started policy: an untrained model "
        "rewards every behaviour about alike; 0: none")
    reward_lr: float = opt(1e-3, "distance-model Adam learning rate")
    reward_wd: float = opt(-1.0,
        "w_d in r = exp(w_d * d^2), d^2 in units of the demonstration's distance to other gaits "
        "(paper: -5 on raw distances): a policy's reward is a mean over steps, and the steeper the "
        "exponential, the more a rollout's few closest steps outweigh its typical distance; late in "
        "a run, as the model pushes agent frames away, -5 ranks rollouts by those outliers")
    adversarial_weight: float = opt(0.1,
        "sampling weight of expert-vs-agent negative pairs relative to each other pair kind (paper: 1): "
        "higher separates agent from expert sooner, until every agent behaviour gets reward 0; 0 leaves "
        "every behaviour rewarded alike")
    video_speed_weight: float = opt(0.3,
        "share of a learned reward that depends on travelling as fast as the demonstration: each step's "
        "reward is the distance model's times (1 - w + w * exp(-((v - v_demo) / |v_demo|)^2)), v the "
        "ground's slide behind the followed robot, measured alike in the demonstration's and the agent's "
        "frames. The distance model paints the ground out and cannot see travel; without this a gait that "
        "drifts backwards scores as one that walks. A product, so travel pays only as far as the motion "
        "looks like the video. Needs a patterned ground (--ground checker): off, with a line, where the "
        "demonstration shows none. 0: none")
    other_demos: str = opt("auto",
        "multi-task clips for the distance model (negatives of another class): \"auto\" = the other "
        "built-in gaits when --demo is one, \"none\", or comma-separated demo sources")


@dataclass
class PPOOptions:
    """PPO (rsl-rl) of the residual policy."""

    steps_per_env: int = opt(64, "env steps per env per iteration (rollout length)")
    learning_rate: float = opt(1e-5,
        "the actor's Adam learning rate at the start, then adapted to a KL target of 0.01 per update "
        "(within 1e-5 .. 1e-2; at std 0.05 it stays at 1e-5). Adam's first steps move every weight by "
        "about the rate whatever the gradient: a start far above where the schedule settles moves a "
        "warm-started policy's mean by about one std in its first update, a setback PPO then has to undo")
    critic_learning_rate: float = opt(1e-3,
        "fixed Adam learning rate of the critic; the KL-adaptive rate is the actor's alone (at std 0.05 "
        "it sits at its 1e-5 floor, which would freeze a critic sharing it). 0: shared, as in rsl-rl")
    entropy_coef: float = opt(0.005, "PPO entropy bonus")
    init_std: float = opt(0.05,
        "initial action std in action units (x the action scale, 0.5 rad on Pupper: 0.025 rad per joint "
        "residual): rollouts stay close to the warm start that walks (motion_imitation fixes 0.125)")
    hidden: str = opt("256,128", "actor/critic MLP hidden sizes, comma separated")
    prior_pull: float = opt(-1.0,
        "with a warm start: after every PPO update the actor's weights move this fraction of the way "
        "back to the warm start's (weight decay towards the prior, half-life ~70 iterations at 0.01; 0: "
        "none): drift on a noisy learned reward fades, a push the reward keeps up holds. -1: 0.01, "
        "but 0 with --reward oracle (an exact reward needs no guard, and the anchor slows its gains). "
        "With --resume: the saved warm start stays the anchor, typed here the pull changes")
    critic_warmup: int = opt(10,
        "iterations at the start of a run that fit the critic alone (actor frozen): PPO's first "
        "advantages come from a critic that knows the warm-started policy")


@dataclass
class EvalOptions:
    """Ground-truth evaluations during training."""

    eval_every: int = opt(25, "ground-truth evaluation every N iterations (0: only at the end)")
    eval_episodes: int = opt(2, "episodes per evaluation (fixed seeds)")
    eval_seconds: float = opt(10.0, "s, length of an evaluation episode")
    alignment_probe: bool = opt(True,
        "with a learned reward: at every evaluation, the rank correlation of the reward with the "
        "ground-truth score over a fixed graded set of rollouts (tracker variants, standing, other gaits,"
        " random; recorded once at the start), logged beside the score")


@dataclass
class TrainArgs(Sectioned):
    """Options of ``python -m virl_quad.train``, one section per concern (flat option names)."""

    run: RunOptions
    env: EnvOptions
    prior: PriorOptions
    distance: DistanceOptions
    ppo: PPOOptions
    eval: EvalOptions


def prior_pull(args: TrainArgs) -> float:
    """The anchor's pull per PPO update (``--prior-pull``; -1: 0.01, 0 with the oracle reward)."""
    if args.ppo.prior_pull >= 0:
        return float(args.ppo.prior_pull)
    return 0.0 if args.run.reward == "oracle" else 0.01


def validate(args: TrainArgs) -> None:
    """Raise ValueError (one line) for inconsistent options."""
    from virl_quad import robots

    robots.get(args.run.robot)
    if args.run.reward not in REWARDS:
        raise ValueError(f"unknown reward {args.run.reward!r}; choose one of: {', '.join(REWARDS)}")
    values = options(args)
    for name in ("warm_start_rounds", "critic_warmup"):
        if values[name] < 0:
            raise ValueError(f"--{name.replace('_', '-')} must be >= 0, got {values[name]}")
    if not 0 <= args.ppo.critic_learning_rate <= 1:
        raise ValueError(f"--critic-learning-rate must lie in [0, 1], got {args.ppo.critic_learning_rate}")
    if not (0 <= args.ppo.prior_pull < 1 or args.ppo.prior_pull == -1):
        raise ValueError(f"--prior-pull must lie in [0, 1) or be -1 (auto), got {args.ppo.prior_pull}")
    if not 0 <= args.run.oracle_speed_weight <= 1:
        raise ValueError(f"--oracle-speed-weight must lie in [0, 1], got {args.run.oracle_speed_weight}")
    if not 0 < args.ppo.init_std <= 2:
        raise ValueError(f"--init-std must lie in (0, 2] action units, got {args.ppo.init_std}")
    for name in ("num_envs", "iterations", "steps_per_env", "save_every", "warm_start_steps"):
        if values[name] < 1:
            raise ValueError(f"--{name.replace('_', '-')} must be >= 1")
    if args.distance.reward_wd >= 0:
        raise ValueError(f"--reward-wd must be negative (r = exp(w_d d^2)), got {args.distance.reward_wd}")
    if args.env.workers not in WORKER_KINDS:
        raise ValueError(f"unknown --workers {args.env.workers!r}; choose one of: {', '.join(WORKER_KINDS)}")
    if args.prior.prior_from not in PRIOR_SOURCES:
        raise ValueError(f"unknown --prior-from {args.prior.prior_from!r}; choose one of: {', '.join(PRIOR_SOURCES)}")
    if args.env.ground not in GROUNDS:
        raise ValueError(f"unknown --ground {args.env.ground!r}; choose one of: {', '.join(GROUNDS)}")
    if not 0 <= args.distance.video_speed_weight <= 1:
        raise ValueError(f"--video-speed-weight must lie in [0, 1], got {args.distance.video_speed_weight}")
    if args.distance.reward_pretrain < 0:
        raise ValueError(f"--reward-pretrain must be >= 0, got {args.distance.reward_pretrain}")
    if args.distance.adversarial_weight < 0:
        raise ValueError(f"--adversarial-weight must be >= 0, got {args.distance.adversarial_weight}")
    if args.run.minutes < 0 or args.env.episode_seconds <= 0 or args.eval.eval_seconds <= 0:
        raise ValueError("--minutes must be >= 0 and episode/eval seconds > 0")
    hidden_sizes(args)


def hidden_sizes(args: TrainArgs) -> list[int]:
    """Parse ``--hidden`` ("256,128") into layer sizes."""
    try:
        sizes = [int(s) for s in args.ppo.hidden.split(",") if s.strip()]
    except ValueError:
        raise ValueError(f"--hidden must be comma-separated integers, got {args.ppo.hidden!r}") from None
    if not sizes or min(sizes) < 1:
        raise ValueError(f"--hidden must list positive sizes, got {args.ppo.hidden!r}")
    return sizes


def rsl_rl_config(args: TrainArgs) -> dict:
    """The rsl-rl 5.x train config dict for these options."""
    hidden = hidden_sizes(args)
    model = {"class_name": "MLPModel", "hidden_dims": hidden, "activation": "elu"}
    return {
        "num_steps_per_env": args.ppo.steps_per_env,
        "save_interval": args.run.save_every,
        "check_for_nan": True,
        "obs_groups": {"actor": ["policy"], "critic": ["policy", "privileged"]},
        "actor": {**model, "obs_normalization": True,
                  "distribution_cfg": {"class_name": "GaussianDistribution", "init_std": args.ppo.init_std,
                                       "std_type": "scalar"}},
        "critic": {**model, "obs_normalization": True},
        "algorithm": {
            "class_name": "virl_quad.training.algorithm:VirlPPO",
            "num_learning_epochs": 5, "num_mini_batches": 4, "clip_param": 0.2,
            "gamma": 0.99, "lam": 0.95, "value_loss_coef": 1.0, "entropy_coef": args.ppo.entropy_coef,
            "learning_rate": args.ppo.learning_rate, "max_grad_norm": 1.0, "schedule": "adaptive",
            "desired_kl": 0.01, "use_clipped_value_loss": True,
            "critic_learning_rate": args.ppo.critic_learning_rate or None,
        },
    }


def to_dict(args: TrainArgs) -> dict:
    """The options as one flat ``{option name: value}`` dict (for checkpoints, report.json and
    metadata: the run's command line, readable without this module)."""
    return options(args)


def from_dict(values: dict) -> TrainArgs:
    """:class:`TrainArgs` from a saved :func:`to_dict` (options it does not name take their
    defaults; options since retired are dropped)."""
    return from_options(TrainArgs, values)
