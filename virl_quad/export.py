"""Export a trained run to a TorchScript policy with metadata (and ONNX when it is one call away).

    python -m virl_quad.export runs/pupper-virl-... --out policies/pupper_trot.pt

Writes ``NAME.pt`` (observation normaliser baked in, deterministic mean action),
``NAME.json`` (see :mod:`virl_quad.policy_io`) and, with ``--onnx``, ``NAME.onnx``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from virl_quad import robots
from virl_quad.cli import UserError, opt, parse, run_main
from virl_quad.policy.contract import PolicyContract
from virl_quad.training.config import TrainArgs, from_dict, hidden_sizes, rsl_rl_config

if TYPE_CHECKING:                                  # torch loads only once the options are good
    from rsl_rl.models import MLPModel


def _actor(contract: PolicyContract, args: TrainArgs) -> MLPModel:
    """An rsl-rl actor of the training architecture for ``contract``'s observation and action sizes."""
    import torch
    from rsl_rl.models import MLPModel
    from tensordict import TensorDict

    obs = TensorDict({"policy": torch.zeros(1, contract.observation_size)}, batch_size=[1])
    cfg = rsl_rl_config(args)["actor"]
    cfg.pop("class_name")
    return MLPModel(obs, {"actor": ["policy"]}, "actor", contract.action_size, **cfg)


def actor_from_checkpoint(data: dict) -> tuple[MLPModel, TrainArgs, PolicyContract]:
    """Rebuild the rsl-rl actor of a checkpoint (eval mode), with the run's options and policy contract."""
    from virl_quad.training import checkpoint

    args = from_dict(data["config"])
    contract = checkpoint.contract_of(data, args.run.robot)
    hidden_sizes(args)
    actor = _actor(contract, args)
    try:
        actor.load_state_dict(data["actor_state_dict"])
    except RuntimeError as exc:
        raise UserError(f"checkpoint actor does not match its config ({str(exc).splitlines()[0][:100]})") from None
    return actor.eval(), args, contract


def default_contract(robot: str, demo_frames: int | None = None, tg=None) -> PolicyContract:
    """The contract of ``virl_quad.envs.make(robot, tg=tg)`` with a demonstration of ``demo_frames``
    frames (None: none): the env's defaults, for untrained policies in tests and dry runs."""
    from virl_quad.envs import EnvConfig, policy_contract

    return policy_contract(robots.get(robot), EnvConfig.make(tg=tg), demo_frames)


def fresh_actor(contract: PolicyContract, hidden: list[int] | tuple[int, ...] = (256, 128), seed: int = 0) -> MLPModel:
    """An untrained actor with the training architecture for ``contract`` (for tests and dry runs)."""
    import torch

    torch.manual_seed(seed)
    return _actor(contract, TrainArgs.make(hidden=",".join(str(h) for h in hidden))).eval()


def export_actor(actor: MLPModel, robot: str, out: str | Path, contract: PolicyContract, demo: dict | None = None,
                 scores: dict | None = None, extra: dict | None = None, onnx: bool = False) -> Path:
    """Script ``actor`` and write ``out`` (.pt) with its metadata (``contract``: how the actor was
    trained to act and what it observes; ONNX on request)."""
    import torch

    from virl_quad.policy_io import metadata_for, save_policy

    out = _checked_out(out)
    spec = robots.get(robot)
    scripted = torch.jit.script(actor.as_jit())
    meta = metadata_for(spec, contract, demo=demo, scores=scores)
    meta.update(extra or {})
    save_policy(scripted, meta, out)
    if onnx:
        _export_onnx(actor, out.with_suffix(".onnx"))
    return out


def _checked_out(out: str | Path) -> Path:
    """``out`` as a Path; UserError unless it ends in .pt."""
    out = Path(out)
    if out.suffix != ".pt":
        raise UserError(f"--out must end in .pt, got {out}")
    return out


def export(run_dir: str | Path, out: str | Path, onnx: bool = False) -> Path:
    """Export the run in ``run_dir`` to ``out`` (``.pt``); returns the path written."""
    run_dir, out = Path(run_dir), _checked_out(out)
    if not run_dir.exists():
        raise UserError(f"run folder {run_dir} does not exist")
    from virl_quad.training import checkpoint

    data = checkpoint.load(run_dir)
    actor, args, contract = actor_from_checkpoint(data)
    report = run_dir / "report.json"
    scores = json.loads(report.read_text()).get("evaluation", {}) if report.exists() else {}
    demo_meta = {"source": args.run.demo}
    demo_file = run_dir / "demo.npz"
    if demo_file.exists():
        from virl_quad.demo.render import load_npz

        d = load_npz(demo_file)
        demo_meta.update({"source": d.source or args.run.demo, "robot": d.robot, "fps": d.fps,
                          "num_frames": d.num_frames, "has_motion": d.motion is not None})
    extra = {"reward": args.run.reward, "iterations": int(data["iteration"]), "env_steps": int(data["env_steps"])}
    return export_actor(actor, args.run.robot, out, contract, demo_meta, scores, extra, onnx)


def _export_onnx(actor: MLPModel, path: Path) -> None:
    import torch

    model = actor.as_onnx(verbose=False).eval()
    try:
        torch.onnx.export(model, model.get_dummy_inputs(), str(path), input_names=model.input_names,
                          output_names=model.output_names, opset_version=18)
    except Exception as exc:  # onnx / onnxscript not installed, or an exporter limitation
        raise UserError(f"ONNX export failed ({str(exc).splitlines()[0][:120]}); "
                        "install the extra: pip install -e '.[onnx]'") from None


@dataclass
class ExportArgs:
    """Options of ``python -m virl_quad.export``."""

    run_dir: str = opt("", "training run folder (holds checkpoint.pt)", positional=True, required=True)
    out: str = opt("", "output policy path, e.g. policies/pupper_trot.pt", required=True)
    onnx: bool = opt(False, "also write NAME.onnx")


def main(argv: list[str] | None = None) -> int:
    """Command line entry."""
    args = parse(ExportArgs, argv, __doc__.split("\n\n")[0], "python -m virl_quad.export")
    path = export(args.run_dir, args.out, args.onnx)
    print(f"exported {path} and {path.with_suffix('.json')}")
    return 0


if __name__ == "__main__":
    run_main(main)
