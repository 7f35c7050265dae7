"""`hrc show TASK.yaml [--json]`: the loaded task, its map and how many plans it admits."""

from __future__ import annotations

import argparse
import json
import math
from typing import Any

from hrc.compile.estimate import DEFAULT_MAX_PLANS, FIXED_SECONDS, estimate, fmt_bytes, fmt_span
from hrc.compile.executors import default_jobs
from hrc.io.task_file import load_task
from hrc.model import Task
from hrc.motion.separation import describe as model_words
from hrc.plans import allocation_count, identical_actions, symmetry_factor

__all__ = ["add_parser", "run", "task_summary"]


def add_parser(sub: Any) -> None:
    p = sub.add_parser("show", help="print a task, its map and its plan count")
    p.add_argument("task", help="task YAML file")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    p.set_defaults(run=run)


def _bound(x: float) -> float | str:
    return "inf" if math.isinf(x) else x  # JSON has no infinity


def task_summary(task: Task) -> dict[str, Any]:
    """A JSON-ready summary of `task`, including ``plan_count`` (exact, or an upper bound when
    ``plan_count_exact`` is false: counting would be slow) and the up-front ``estimate`` of a compile
    (bytes on disk per ``--stnu`` mode, CPU seconds low and high, `hrc.compile.estimate`)."""
    ws = task.workspace
    est = estimate(task)
    return {
        "task": task.name,
        "file": task.source,
        "deadline": task.deadline,
        "safety_margin": task.safety_margin,
        "agents": [{"id": a.id, "kind": a.kind.value, "radius": a.radius, "speed": a.speed, "start": a.start,
                    "travel_slack": a.travel_slack} for a in task.agents],
        "actions": [{"id": a.id, "name": a.name, "agents": list(a.agents), "phases": [
            {"id": p.id, "location": p.location, "duration": {ag: [iv.lb, iv.ub] for ag, iv in p.durations}}
            for p in a.phases]} | ({"roles": dict(a.roles)} if a.joint else {}) for a in task.actions],
        "precedence": [[str(p.before), str(p.after)] for p in task.precedence],
        "constraints": [{"from": str(c.source), "to": str(c.target),
                         "bounds": [c.bounds.lb, _bound(c.bounds.ub)]} for c in task.constraints],
        "preferences": [{"from": str(p.source), "to": str(p.target), "domain": [p.domain.lb, p.domain.ub],
                         "kind": p.kind.value, "coefficients": list(p.coefficients)} for p in task.preferences],
        "map": {"name": ws.name, "file": ws.source, "bounds": list(ws.bounds),
                "obstacles": len(ws.obstacles), "floorplan": ws.floorplan,
                "locations": {loc.id: [loc.x, loc.y] for loc in ws.locations}},
        "plan_count": est.plans.value,
        "allocations": allocation_count(task),
        "plan_count_exact": est.plans.exact,
        "estimate": {"disk_bytes": {mode: est.disk(mode) for mode in est.stnu_bytes},
                     "cpu_seconds": [round(est.cpu_seconds[0], 1), round(est.cpu_seconds[1], 1)],
                     "fixed_seconds": list(FIXED_SECONDS),
                     "max_plans_default": DEFAULT_MAX_PLANS},
        "identical_actions": [list(g) for g in identical_actions(task)],
        "symmetry_factor": symmetry_factor(task),
    } | ({} if task.safety is None else {"separation": model_words(task)})  # a task with safety: only


def _text(s: dict[str, Any]) -> str:
    lines = [f"task {s['task']}  ({s['file']})"]
    deadline = "none" if s["deadline"] is None else f"{s['deadline']:g} s"
    lines.append(f"  makespan deadline: {deadline}; safety margin: {s['safety_margin']:g} m")
    if "separation" in s:
        lines.append(f"  between the co-workers: {s['separation']}")
    lines.append("agents:")
    for a in s["agents"]:
        pace = f", travel up to x{a['travel_slack']:g}" if a["kind"] == "human" else ""
        lines.append(f"  {a['id']:<8} {a['kind']:<6} radius {a['radius']:g} m, speed {a['speed']:g} m/s{pace}, "
                     f"starts at {a['start']}")
    lines.append("actions:")
    for a in s["actions"]:
        if "roles" in a:  # a joint action (issue 37): every agent of it at once
            who = ", ".join(f"{role} {ag}" for role, ag in a["roles"].items())
            lines.append(f"  {a['id']:<10} {a['name']}  (by all at once: {who})")
        else:
            lines.append(f"  {a['id']:<10} {a['name']}  (by {', '.join(a['agents'])})")
        for p in a["phases"]:
            durs = ", ".join(f"{ag} [{lb:g}, {ub:g}] s" for ag, (lb, ub) in p["duration"].items())
            lines.append(f"    {p['id']:<8} at {p['location']:<4} {durs}")
    if s["precedence"]:
        lines.append("precedence:")
        lines.extend(f"  {b} -> {a}" for b, a in s["precedence"])
    if s["constraints"]:
        lines.append("temporal constraints (lb <= T(to) - T(from) <= ub):")
        lines.extend(f"  {c['from']} -> {c['to']} in [{c['bounds'][0]:g}, {float(c['bounds'][1]):g}] s"
                     for c in s["constraints"])
    if s["preferences"]:
        lines.append("preferences:")
        lines.extend(f"  {p['from']} -> {p['to']} on [{p['domain'][0]:g}, {p['domain'][1]:g}] s: {p['kind']} "
                     f"{p['coefficients']}" for p in s["preferences"])
    m = s["map"]
    xmin, ymin, xmax, ymax = m["bounds"]
    lines.append(f"map {m['name']}  ({m['file']}): {xmax - xmin:g} m x {ymax - ymin:g} m, "
                 f"{m['obstacles']} obstacles" + (f" (floor plan {m['floorplan']})" if m["floorplan"] else ""))
    lines.append("  locations: " + ", ".join(f"{k} ({x:g}, {y:g})" for k, (x, y) in m["locations"].items()))
    e = s["estimate"]
    jobs = default_jobs()
    lo, hi = (f + t / jobs for f, t in zip(e["fixed_seconds"], e["cpu_seconds"], strict=True))
    disk = e["disk_bytes"]
    lines.append(f"compile estimate: {fmt_span(lo, hi, ' - ', about=True)} on {jobs} core{'s' * (jobs > 1)} "
                 "(start-up, path planning and the report included; longer on a busy machine); on disk "
                 f"{fmt_bytes(disk['graphml'])} (--stnu archive: {fmt_bytes(disk['archive'])}, none: "
                 f"{fmt_bytes(disk['none'])})")
    if s["plan_count"] > e["max_plans_default"]:
        lines.append(f"  more than {e['max_plans_default']:,} plans: `hrc compile` searches for the best plans "
                     "instead (--plans best:K, docs/search.md); every plan only with --plans all and a --max-plans "
                     "that allows it; or use --executor (Dask), or --pin ACTION=AGENT or --symmetry to compile fewer")
    if s["identical_actions"]:
        groups = "; ".join(", ".join(g) for g in s["identical_actions"])
        lines.append(f"  identical actions ({groups}): `hrc compile --symmetry` compiles one plan in "
                     f"{s['symmetry_factor']}")
    count = f"{s['plan_count']}" if s["plan_count_exact"] else f"at most {s['plan_count']} (exact count too slow)"
    lines.append(f"plans: {count} ({s['allocations']:,} allocations x valid per-agent sequences; "
                 "`hrc compile --best-per-allocation K` keeps only the K best of each)")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    summary = task_summary(load_task(args.task))
    print(json.dumps(summary, indent=2) if args.json else _text(summary))
    return 0
