"""Check each robot's URDF, Pinocchio model, PyBullet model and spec against one another.

    python -m virl_quad.check --robot {pupper,laikago,all} [--samples 100] [--seed 0]

Prints, per robot, the joint mapping (canonical index, URDF name, PyBullet
index, Pinocchio joint id / idx_q / nq) and one row per check with PASS/FAIL
and its figures. Exit status: 0 all checks pass, 1 some check fails,
2 bad command line (e.g. an unknown robot).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass

from virl_quad import robots
from virl_quad.cli import opt, parser_from_dataclass
from virl_quad.quiet import import_pybullet_quietly

CHOICES = (*robots.names(), "all")


@dataclass
class CheckArgs:
    """Options of ``python -m virl_quad.check``."""

    robot: str = opt("all", "robot to check: " + ", ".join(CHOICES))
    samples: int = opt(100, "random configurations for the FK comparison")
    seed: int = opt(0, "random seed")


def _parser() -> argparse.ArgumentParser:
    return parser_from_dataclass(CheckArgs, description=__doc__.split("\n\n")[0], prog="python -m virl_quad.check")


def format_mapping(report) -> list[str]:
    """The joint mapping table of one robot."""
    head = f"  {'#':>2}  {'joint':<13} {'URDF name':<32} {'type':<10} {'PyBullet':>8} {'Pin id':>6} " \
           f"{'idx_q':>5} {'nq':>2} {'idx_v':>5}  axis(base, q=0)"
    lines = [head]
    for r in report.mapping:
        lines.append(f"  {r['index']:>2}  {r['joint']:<13} {r['name']:<32} {str(r['urdf_type']):<10} "
                     f"{r['pybullet']:>8} {r['pin_id']:>6} {r['idx_q']:>5} {r['nq']:>2} {r['idx_v']:>5}  {r['axis']}")
    return lines


def format_report(report) -> list[str]:
    """The check table of one robot: one row per check."""
    width = max([len(r.name) for r in report.results] + [5])
    lines = [f"  {'check':<{width}}  result  figures"]
    for r in report.results:
        lines.append(f"  {r.name:<{width}}  {'PASS' if r.ok else 'FAIL':<6}  {r.figures}")
        lines += [f"  {'':<{width}}          ! {d}" for d in r.details]
    return lines


def main(argv: list[str] | None = None) -> int:
    """Run the checks for the chosen robot(s), print the tables; 0 when all pass, 1 otherwise."""
    args = _parser().parse_args(argv)
    if args.robot not in CHOICES:
        _parser().error(f"unknown robot {args.robot!r}; choose one of: {', '.join(CHOICES)}")
    if args.samples < 1:
        _parser().error(f"--samples must be >= 1, got {args.samples}")
    import_pybullet_quietly()
    from virl_quad.kinematics.checks import run_checks

    names = robots.names() if args.robot == "all" else (args.robot,)
    reports = []
    for name in names:
        spec = robots.get(name)
        t0 = time.perf_counter()
        print(f"checking {name} ({spec.urdf_path}) ...", flush=True)
        report = run_checks(spec, samples=args.samples, seed=args.seed)
        reports.append(report)
        print(f"\n== {name}: {sum(r.ok for r in report.results)}/{len(report.results)} checks pass "
              f"({time.perf_counter() - t0:.1f} s) ==")
        if report.mapping:
            print("\n".join(format_mapping(report)))
            print()
        print("\n".join(format_report(report)))
        print(flush=True)
    ok = all(r.ok for r in reports)
    summary = ", ".join(f"{r.spec.name} {'PASS' if r.ok else 'FAIL'}" for r in reports)
    print(f"result: {summary} -> {'all checks pass' if ok else 'SOME CHECKS FAIL'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
