"""Distil the privileged reference tracker into a proprioceptive policy (behaviour cloning, DAgger).

    python -m virl_quad.distill --robot pupper --out policies/pupper_trot_tracker_bc.pt

NOT the VIRL method: the teacher (:mod:`virl_quad.evaluation.tracker`) reads the reference joint
angles of the demonstration, which a video does not have. What it gives is a policy of the
training architecture, on the training observation (the one builder), exported in the
training format, that walks: a yardstick for what a proprioceptive MLP can do on this
robot model, and a known-good policy to test the deployment chain with (the HAL and the
policy server must reproduce what it does in the training environment).

The DAgger machinery is :mod:`virl_quad.training.dagger`; this module is its command line,
which answers a bad option before torch and the simulator load.
"""

from __future__ import annotations

import dataclasses
import json
import sys
from dataclasses import dataclass
from pathlib import Path

from virl_quad import robots
from virl_quad.cli import UserError, dataclass_from_args, opt, parser_from_dataclass, run_main
from virl_quad.evaluation.tracker import DEFAULT_GAIN, DEFAULT_LEAD


@dataclass
class DistillArgs:
    """Options of ``python -m virl_quad.distill`` (field comments are the CLI help)."""

    robot: str = opt("pupper", "robot name (pupper, laikago)")
    demo: str = opt("trot", "built-in gait or motion file (it needs a reference motion)")
    out: str = opt("", "exported policy NAME.pt; default policies/<robot>_<demo>_tracker_bc.pt")
    rounds: int = opt(6, "DAgger rounds (round 0: the tracker drives)")
    steps: int = opt(5000, "control steps gathered per round")
    epochs: int = opt(100, "passes over the data per refit (cosine learning-rate decay)")
    lr: float = opt(1e-3, "Adam learning rate")
    batch: int = opt(512, "minibatch size")
    hidden: str = opt("256,128", "hidden layer sizes (the training default)")
    gain: float = opt(DEFAULT_GAIN, "tracker feedback gain on the joint error")
    lead: float = opt(DEFAULT_LEAD, "s the tracker's feed-forward reference runs ahead")
    blind_last_action: bool = opt(True,
        "the student ignores the last-action input (no copying the teacher's last action)")
    noise: float = opt(0.1,
        "std of Gaussian noise on the executed action (action units): wider states, fewer falls")
    randomize: bool = opt(False,
        "domain randomisation while gathering (off: the nominal robot, as the sim HAL)")
    max_latency: float | None = opt(None,
        "s, largest observation delay drawn with --randomize (unset: the robot's own range)")
    seed: int = opt(0, "random seed")
    quiet: bool = opt(False, "no progress lines")


def main(args: DistillArgs) -> int:
    """Distil, export, print where the policy went; returns the exit code."""
    robots.get(args.robot)                        # unknown robot: one line, exit 2
    if args.rounds < 1 or args.steps < 1 or args.epochs < 1 or args.batch < 1:
        raise UserError("--rounds, --steps, --epochs and --batch must be >= 1")
    if args.max_latency is not None and not 0.0 <= args.max_latency <= 0.2:
        raise UserError(f"--max-latency must be between 0 and 0.2 s, got {args.max_latency}")
    out = Path(args.out or f"policies/{args.robot}_{Path(args.demo).stem}_tracker_bc.pt")
    log = (lambda *a: None) if args.quiet else (lambda m: print(m, flush=True))
    import torch

    from virl_quad.export import export_actor
    from virl_quad.training.dagger import distil

    torch.manual_seed(args.seed)
    torch.set_num_threads(1)
    actor, info = distil(args, log)
    d = info["demo"]
    demo_meta = {"source": d.source or args.demo, "robot": d.robot, "fps": d.fps, "num_frames": d.num_frames,
                 "has_motion": True}
    extra = {"reward": "none (behaviour cloning of the privileged tracker; not VIRL)",
             "distill": dataclasses.asdict(args),
             "distill_rounds": info["rounds"], "distill_student": info["student"]}
    path = export_actor(actor, args.robot, out, info["contract"], demo_meta, {}, json.loads(json.dumps(extra)))
    log(f"wrote {path} (and {path.with_suffix('.json').name}); evaluate it with "
        f"python -m virl_quad.evaluate --policy {path}")
    return 0


def cli(argv: list[str] | None = None) -> None:
    """Command-line entry point (help from the :class:`DistillArgs` field comments)."""
    parser = parser_from_dataclass(DistillArgs, description=__doc__.split("\n\n")[0],
                                   prog="python -m virl_quad.distill")
    ns = parser.parse_args(sys.argv[1:] if argv is None else argv)
    run_main(lambda: main(dataclass_from_args(DistillArgs, ns)))


if __name__ == "__main__":
    cli()
