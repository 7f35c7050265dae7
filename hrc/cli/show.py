"""`hrc show TASK.yaml [--json]`: the loaded task, its map and how many plans it admits.
`hrc show OUT [--json]`: an `hrc compile` output at a glance (task, counts, the best plans);
`hrc show OUT --plan ID [--json]`: one plan's detail, read from where it lies (`hrc.compile.output.read_plan`:
one line of ``compiled.json`` or ``plans.jsonl``, whatever the plan count)."""

from __future__ import annotations

import argparse
import itertools
import json
import math
from pathlib import Path
from typing import Any

from hrc.compile.estimate import (
    CALIBRATION_MAX_PLANS,
    DEFAULT_MAX_PLANS,
    FIXED_SECONDS,
    calibrate,
    estimate,
    fmt_bytes,
    fmt_seconds,
    fmt_span,
)
from hrc.compile.executors import default_jobs
from hrc.errors import HrcError, InputError
from hrc.io.task_file import load_task
from hrc.model import Task
from hrc.motion.separation import describe as model_words
from hrc.plans import allocation_count, identical_actions, symmetry_factor

__all__ = ["add_parser", "run", "task_summary"]


def add_parser(sub: Any) -> None:
    p = sub.add_parser("show", help="print a task, its map and its plan count; or a compile output, or one of "
                                    "its plans")
    p.add_argument("task", help="task YAML file, or an hrc compile output folder")
    p.add_argument("--plan", metavar="ID", help="with an output folder: that plan's detail (allocation, order, class, "
                                                "makespan, motions, passing orders, waiting places, STNU)")
    p.add_argument("--top", type=int, default=10, metavar="N", help="with an output folder: the N best plans (10)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    p.add_argument("--no-calibrate", action="store_true",
                   help="estimate the compile from the task's size alone (a wide range) instead of compiling a sample "
                        "of its plans here (a few seconds once, then cached)")
    p.set_defaults(run=run)


def _bound(x: float) -> float | str:
    return "inf" if math.isinf(x) else x  # JSON has no infinity


def task_summary(task: Task, calibrated: bool = False) -> dict[str, Any]:
    """A JSON-ready summary of `task`, including ``plan_count`` (exact, or an upper bound when
    ``plan_count_exact`` is false: counting would be slow) and the up-front ``estimate`` of a compile
    (bytes on disk per ``--stnu`` mode, CPU seconds low and high, `hrc.compile.estimate`; with
    `calibrated`, a sample of plans compiled here and the wall seconds of ``hrc compile`` on this
    machine's cores it implies, ``wall_seconds``, and what the sample measured, ``calibration``)."""
    ws = task.workspace
    est = estimate(task)
    measured: dict[str, Any] = {}
    if calibrated and (not est.plans.exact or est.plans.value > CALIBRATION_MAX_PLANS):
        # a compile of every plan is out of reach (and finding a spread sample among billions is slow itself)
        measured = {"calibration_error": f"more than {CALIBRATION_MAX_PLANS:,} plans: no sample"}
    elif calibrated:
        try:
            cal = calibrate(task)
        except HrcError as err:  # e.g. an unreachable location: the compile would say so too
            measured = {"calibration_error": str(err)}
        else:
            jobs = default_jobs()
            n = est.plans.value
            measured = {"wall_seconds": round(cal.wall(n, jobs), 1), "workers": jobs,
                        "wall_seconds_now": round(cal.wall(n, jobs, now=True), 1),
                        "wall_seconds_archive": round(cal.wall(n, jobs, "archive"), 1),
                        "wall_seconds_archive_no_report": round(cal.wall(n, jobs, "archive", report=False), 1),
                        "calibration": {"plans": cal.plans, "seconds_per_plan": round(cal.pace, 5),
                                        "first_seconds_per_plan": round(cal.first_pace, 5),
                                        "wall_ratio": round(cal.wall_ratio, 2),
                                        "line_bytes": round(cal.line_bytes),
                                        "paths_seconds": round(cal.paths_seconds, 2)},
                        "compiled_json_bytes": _json_bytes(n, cal.line_bytes)}
    return {
        "task": task.name,
        "file": task.source,
        "deadline": task.deadline,
        "safety_margin": task.safety_margin,
        "agents": [{"id": a.id, "kind": a.kind.value, "radius": a.radius, "speed": a.speed, "start": a.start,
                    "travel_slack": a.travel_slack} for a in task.agents],
        "actions": [{"id": a.id, "name": a.name, "agents": list(a.agents), "phases": [
            {"id": p.id, "location": p.location, "duration": {ag: [iv.lb, iv.ub] for ag, iv in p.durations}}
            for p in a.phases]} | ({"roles": {role: (c[0] if len(c) == 1 else list(c)) for role, c in a.roles}}
                                       | ({"agents_needed": a.needed} if a.needed < len(a.roles) else {})
                                       if a.joint else {}) for a in task.actions],
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
                     "max_plans_default": DEFAULT_MAX_PLANS} | measured,
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
            who = ", ".join(f"{role} {ag if isinstance(ag, str) else ' or '.join(ag)}"
                            for role, ag in a["roles"].items())
            if "agents_needed" in a:  # any k of its agents (the plan chooses the crew)
                lines.append(f"  {a['id']:<10} {a['name']}  (by any {a['agents_needed']} of {', '.join(a['agents'])} "
                             "at once)")
            else:
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
    cores = f"{jobs} core{'s' * (jobs > 1)}"
    if "wall_seconds" in e:
        c = e["calibration"]
        archive, bare = fmt_seconds(e["wall_seconds_archive"]), fmt_seconds(e["wall_seconds_archive_no_report"])
        lines.append(f"compile estimate: about {fmt_seconds(e['wall_seconds'])} on {cores} (start-up, path planning "
                     f"and the report included; --stnu archive: {archive}, with --no-report too: {bare}), from "
                     f"{c['plans']} sample plans "
                     f"compiled here at {1000 * c['seconds_per_plan']:.1f} ms each (an idle machine"
                     + (f"; at the load the sample saw, about {fmt_seconds(e['wall_seconds_now'])}"
                        if c["wall_ratio"] >= 1.3 else "")
                     + f"); compiled.json {fmt_bytes(e['compiled_json_bytes'])}")
    else:
        why = f" ({e['calibration_error']})" if "calibration_error" in e else ""
        lines.append(f"compile estimate: {fmt_span(lo, hi, ' - ', about=True)} on {cores} "
                     f"(start-up, path planning and the report included; longer on a busy machine; no sample{why})")
    lines.append(f"  on disk about {fmt_bytes(disk['graphml'])} (--stnu archive: {fmt_bytes(disk['archive'])}, none: "
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
    path = Path(args.task)
    if path.is_dir() and (args.plan is not None or (path / "compiled.json").exists()):
        return _run_output(args)  # else a folder given as a task: that error, as before
    if args.plan is not None:
        raise InputError(args.task, "", "--plan reads an output folder of hrc compile, not a task file")
    summary = task_summary(load_task(args.task), calibrated=not args.no_calibrate)
    print(json.dumps(summary, indent=2) if args.json else _text(summary))
    return 0


def _json_bytes(plans: int, line: float) -> int:
    """``compiled.json``'s size for `plans` lines of `line` bytes: all of them up to `INLINE_MAX_BYTES`,
    else a row each (about 200 bytes, at most `ROWS_MAX`) and the lines in ``plans.jsonl``."""
    from hrc.compile.output import INLINE_MAX_BYTES, ROWS_MAX  # lazily: every hrc command imports this module

    whole = int(plans * line)
    return whole if whole <= INLINE_MAX_BYTES else 200 * min(plans, ROWS_MAX)


# ------------------------------------------------------------------------------------- an output folder
def _run_output(args: argparse.Namespace) -> int:
    from hrc.compile.output import read_header, read_plan  # lazily: every hrc command imports this module

    folder = Path(args.task)
    header = read_header(folder)
    if args.plan is None:
        top = _top(folder, max(args.top, 0))
        print(json.dumps({"header": header, "top": top}, indent=2) if args.json else _output_text(folder, header, top))
        return 0
    plan = read_plan(folder, args.plan)
    if plan is None:
        total = sum(header.get("counts", {}).values())
        raise InputError(str(folder / "compiled.json"), "plans", f"no plan {args.plan!r} among its {total:,} plans "
                                                                 f"(hrc show {folder} lists the best)")
    where = _stnu_where(folder, header, plan)
    if args.json:
        print(json.dumps(plan | {"stnu_location": where}, indent=2))
    else:
        print(_plan_text(folder, header, plan, where))
    return 0


def _top(folder: Path, n: int) -> list[dict[str, Any]]:
    """The first `n` plans of ``compiled.json`` (rank order) as its lines give them: whole entries, or a
    split output's rows (id, rank, class, sequences, makespan, preference); read line by line."""
    out = []
    with open(folder / "compiled.json", "rb") as f:
        for line in itertools.islice((x for x in f if x.startswith(b'{"id":')), n):
            try:
                row = json.loads(line.rstrip(b",\n"))
            except ValueError as err:
                raise InputError(str(folder / "compiled.json"), "plans",
                                 f"a line is not a plan's JSON ({err})") from err
            out.append({k: row[k] for k in ("id", "rank", "class", "sequences", "makespan", "preference") if k in row})
    return out


def _stnu_where(folder: Path, header: dict[str, Any], plan: dict[str, Any]) -> str | None:
    """Where the plan's STNU is: its file, its member of the archive, or None (not written)."""
    rel = plan.get("stnu")
    if not rel:
        return None
    if header.get("stnu_files") == "archive":
        return f"{folder / str(header.get('stnu_archive', 'stnu.zip'))}: member {rel}"
    return str(folder / rel)


def _secs(x: Any) -> str:
    return "-" if x is None else f"{x:g} s"


def _span(m: Any) -> str:
    return "no schedule" if not m else f"{m[0]:g}-{m[1]:g} s"


def _output_text(folder: Path, header: dict[str, Any], top: list[dict[str, Any]]) -> str:
    task, counts = header["task"], header.get("counts", {})
    total = sum(counts.values())
    lines = [f"compiled {task['name']} ({folder}): {total:,} plans, "
             + ", ".join(f"{v:,} {k}" for k, v in counts.items())
             + (" (partial: the compile was interrupted)" if header.get("partial") else "")]
    lines.append(f"  task digest {task['digest']}, seed {header.get('seed')}, "
                 f"options {json.dumps(header.get('options'))}")
    if "sensing" in header:
        lines.append(f"  sensing: {json.dumps(header['sensing'])}")
    where = header.get("plan_lines")
    lines.append("  each plan's detail: " + (f"{folder / where['path']} (one line a plan, rank order), "
                                              "compiled.json lists a row per plan" if isinstance(where, dict)
                                              else "in compiled.json"))
    if top:
        lines.append(f"best {len(top)}:")
        for r in top:
            seqs = "; ".join(f"{a}: {' -> '.join(s) or '-'}" for a, s in r.get("sequences", {}).items())
            lines.append(f"  {r['rank']:>4}. {r['id']}  {r['class']:<12} {_span(r.get('makespan')):<16} {seqs}")
    lines.append(f"one plan: hrc show {folder} --plan ID")
    return "\n".join(lines)


def _occupancy(o: dict[str, Any]) -> str:
    if o.get("kind") == "travel":
        return f"leg {o.get('leg')} {o.get('from')} -> {o.get('to')}"
    return f"at {o.get('at')} (leg {o.get('leg')})"


def _plan_text(folder: Path, header: dict[str, Any], p: dict[str, Any], stnu: str | None) -> str:
    total = sum(header.get("counts", {}).values())
    lines = [f"plan {p['id']} of {header['task']['name']} ({folder}): rank {p['rank']:,} of {total:,}, {p['class']}"
             + (f" (at observation delay 0: {p['class_at_delay_0']})" if "class_at_delay_0" in p else "")]
    if p.get("explanation"):
        lines.append(f"  why: {p['explanation']}")
    lines.append(f"  makespan {_span(p.get('makespan'))} (earliest-worst case), "
                 f"nominal {_secs(p.get('nominal_makespan'))}; idle "
                 + ", ".join(f"{a} {t:g} s" for a, t in p.get("idle", {}).items())
                 + (f"; preference {p['preference']:g}" if p.get("preference") is not None else ""))
    # each agent's actions from its order: a joint action is every agent's of its crew (the allocation
    # names only the crew's lead, issue 37), marked so
    by_agent: dict[str, list[str]] = {}
    for action, agent in p.get("allocation", {}).items():
        by_agent.setdefault(agent, []).append(action)
    seqs = p.get("sequences", {})
    if seqs:
        times = {x: sum(x in seq for seq in seqs.values()) for x in p.get("allocation", {})}
        by_agent = {a: [f"{x} (joint)" if times.get(x, 0) > 1 else x for x in seq] for a, seq in seqs.items() if seq}
    lines.append("  allocation: " + "; ".join(f"{a}: {', '.join(sorted(acts))}" for a, acts in by_agent.items()))
    lines.append("  order:")
    lines.extend(f"    {a}: {' -> '.join(seq) or '(nothing)'}" for a, seq in p.get("sequences", {}).items())
    motions = p.get("motions", [])
    lines.append(f"  motions ({len(motions)}):")
    for m in motions:
        extra = []
        if m.get("detour"):
            extra.append(f"detour {m['detour']['round']}")
        if m.get("park"):
            extra.append(f"waits at {m['park']['at']}")
        if m.get("speed"):
            extra.append(f"speed {m['speed']}")
        lines.append(f"    {m['agent']:<6} leg {m['leg']:>2} {m['from']} -> {m['to']} for {m['action']}.{m['phase']}: "
                     f"{m['time']:g} s (free {m['free_time']:g} s)" + (f", {', '.join(extra)}" if extra else ""))
    parks = [m for m in motions if m.get("park")]
    lines.append("  waiting places: " + ("; ".join(f"{m['agent']} waits at {m['park']['at']} on leg {m['leg']} "
                                                    f"({m['from']} -> {m['to']}; {m['park']['time']:g} s of its moving "
                                                    "time to get there)" for m in parks) or "none"))
    passing = p.get("passing", [])
    pat = p.get("pattern", {})
    lines.append(f"  passing orders ({len(passing)} in the STNU; {pat.get('implied', 0)} implied by the plan, "
                 f"{pat.get('conflicts', 0)} conflicts, {pat.get('candidates', 0)} candidate patterns"
                 + ("" if pat.get("exhaustive", True) else ", search not exhaustive") + "):")
    for o in passing:
        c = o.get("constraint", {})
        x, y = o.get("point", [0, 0])
        # a task of more than two agents names each occupancy's agent (issue 37): the slot name otherwise
        who = {k: o[k].get("agent", k) for k in ("robot", "human")}
        lines.append(f"    {who[o['first']]} first ({o['how']}) at ({x:g}, {y:g}): {who['robot']} "
                     f"{_occupancy(o['robot'])}, {who['human']} {_occupancy(o['human'])}; T({c.get('to')}) - "
                     f"T({c.get('from')}) >= {c.get('min') or 0.0:g} s")
    meet = p.get("people_meet")
    if meet is not None:
        lines.append(f"  where two people may meet ({len(meet)}; left to them, no order planned):")
        lines.extend(f"    {m['first']['agent']} {_occupancy(m['first'])}, {m['second']['agent']} "
                     f"{_occupancy(m['second'])} near ({m['point'][0]:g}, {m['point'][1]:g})" for m in meet)
    lines.append(f"  STNU: {stnu or 'not written (--stnu none)'}")
    return "\n".join(lines)
