"""`hrc paths TASK.yaml [--json] [--seed N] [--out FILE.png] [--plan PLAN_ID]`: planned travel paths.

Text: a table of agent / from / to / length / duration. ``--json``: one object an outside checker can
verify without the YAML (world, agents with their clearance, every path with its points); with
``--plan`` it also carries that plan's motion pattern (routes, detours, passing orders: what
`hrc compile` chooses for it). ``--out``: a PNG of the paths (of the plan's two routes with its detours
and the places where one agent waits for the other, with ``--plan``), written atomically.
"""

from __future__ import annotations

import argparse
import errno
import json
import os
from typing import TYPE_CHECKING, Any

from hrc.errors import InputError
from hrc.io.atomic import write_bytes_atomic
from hrc.io.task_file import load_task
from hrc.model import Plan, Task
from hrc.motion import PathLibrary, plan_paths
from hrc.motion.paths import agent_pairs
from hrc.plans import generate_plans
from hrc.report.summary import PASSING_HOW, passing_words

if TYPE_CHECKING:
    from hrc.compile.motion_pattern import PlanChoice

__all__ = ["add_parser", "paths_summary", "run"]


def add_parser(sub: Any) -> None:
    p = sub.add_parser("paths", help="plan and show every travel path of a task (OMPL)")
    p.add_argument("task", help="task YAML file")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    p.add_argument("--seed", type=int, default=0, help="planner seed (default 0)")
    p.add_argument("--out", metavar="FILE.png", help="draw the map and the paths to this PNG")
    p.add_argument("--plan", metavar="PLAN_ID", help="also show this plan's routes, detours and passing orders")
    p.set_defaults(run=run)


def _find_plan(task: Task, plan_id: str) -> Plan:
    for plan in generate_plans(task):
        if plan.id == plan_id:
            return plan
    raise InputError(task.source, "--plan", f"no plan with id '{plan_id}' (see `hrc paths` output ids "
                                            f"or hrc.plans.generate_plans)")


def _pattern_json(choice: PlanChoice) -> dict[str, Any]:
    pattern = choice.pattern
    return {
        "class": choice.classification.plan_class.value,
        "motions": [{"agent": m.agent, "leg": m.leg, "from": m.origin, "to": m.target, "free_time": m.free_time,
                     "time": m.time, "detour": m.via or None, "points": [list(q) for q in m.points]}
                    for m in pattern.motions],
        "passing": [{"order": o.describe(), "first": o.first, "how": o.how, "point": list(o.conflict.point),
                     "min_gap": o.separation.gap} for o in pattern.constrained],
        "passing_words": [{"how": how, "text": text, "points": [list(q) for q in points]}
                          for how, text, points in passing_words(pattern.constrained)],
    }


def paths_summary(task: Task, paths: PathLibrary, plan: Plan | None = None,
                  choice: PlanChoice | None = None) -> dict[str, Any]:
    """The JSON-ready object of ``hrc paths --json`` (paths in task agent order, then pair order)."""
    ws = task.workspace
    out: dict[str, Any] = {
        "seed": paths.seed,
        "world": {"bounds": list(ws.bounds), "obstacles": [[list(p) for p in o.polygon] for o in ws.obstacles]},
        "locations": {loc.id: [loc.x, loc.y] for loc in ws.locations},
        "agents": {a.id: {"radius": a.radius, "clearance": a.radius + task.safety_margin, "speed": a.speed}
                   for a in task.agents},
        "paths": [],
    }
    for agent in task.agents:
        for o, t in agent_pairs(task, agent.id):
            p = paths.get(agent.id, o, t)
            out["paths"].append({"agent": agent.id, "from": o, "to": t, "start": list(p.points[0]),
                                 "goal": list(p.points[-1]), "length": p.length, "duration": p.duration,
                                 "points": [list(q) for q in p.points]})
    if plan is not None and choice is not None:
        out["plan"] = {"id": plan.id, "sequences": {a: list(s) for a, s in plan.sequences}} | _pattern_json(choice)
    return out


def _text(s: dict[str, Any]) -> str:
    lines = [f"{'agent':<8} {'from':<5} {'to':<5} {'length m':>9} {'duration s':>11} {'vertices':>9}"]
    for p in s["paths"]:
        lines.append(f"{p['agent']:<8} {p['from']:<5} {p['to']:<5} {p['length']:9.3f} {p['duration']:11.3f} "
                     f"{len(p['points']):9d}")
    if "plan" in s:
        lines.append(f"plan {s['plan']['id']}: " + "; ".join(f"{a}: {' '.join(q) or '(idle)'}"
                                                          for a, q in s["plan"]["sequences"].items()))
        lines.append(f"class {s['plan']['class']}")
        lines.append(f"{'agent':<8} {'leg':>3} {'from':<5} {'to':<5} {'free s':>8} {'time s':>8}  route")
        for m in s["plan"]["motions"]:
            route = f"detour round {m['detour']}" if m["detour"] else "shortest"
            lines.append(f"{m['agent']:<8} {m['leg']:>3} {m['from']:<5} {m['to']:<5} {m['free_time']:8.2f} "
                         f"{m['time']:8.2f}  {route}")
        words = s["plan"]["passing_words"]
        lines.append(f"passing orders: {len(words)}, each once (numbered as on the --out figure)" if words
                     else "passing orders: none needed")
        for how, heading in PASSING_HOW.items():
            mine = [(k, w) for k, w in enumerate(words, start=1) if w["how"] == how]
            if mine:
                lines.append(f" {heading}:")
                lines += [f"  {k}. {w['text'][0].upper()}{w['text'][1:]}" for k, w in mine]
    return "\n".join(lines)


def _check_out(out: str) -> None:
    """Before any planning: the picture is a PNG, so the name must say .png, and it goes to a file."""
    if os.path.isdir(out):
        raise IsADirectoryError(errno.EISDIR, "is a folder; expected a file name", out)
    if not out.lower().endswith(".png"):
        raise InputError(out, "--out", "expected a file name ending in .png (the picture is written as PNG)")


def run(args: argparse.Namespace) -> int:
    if args.out:
        _check_out(args.out)
    task = load_task(args.task)
    paths = plan_paths(task, seed=args.seed)
    plan = _find_plan(task, args.plan) if args.plan else None
    choice = None
    if plan is not None:
        from hrc.compile.motion_pattern import choose_pattern

        choice = choose_pattern(task, plan, paths)
    summary = paths_summary(task, paths, plan, choice)
    if args.out:
        from hrc.report.paths_figure import paths_png

        write_bytes_atomic(args.out, paths_png(task, paths, plan, choice))
    print(json.dumps(summary) if args.json else _text(summary))
    return 0
