"""``report.md``: the report as GitHub-flavoured Markdown (tables, relative image and network links)."""

from __future__ import annotations

from hrc.report.separation import COST_HEADER, cost_cells
from hrc.report.summary import (
    CLASS_MEANING,
    INLINE_LINKS,
    MODEL_ASSUMPTIONS,
    PREFERENCE_HEADER,
    PREFERENCE_MEANING,
    STATS_HEADER,
    ReportData,
    allocation_legend,
    fmt_detour,
    fmt_idle,
    fmt_makespan,
    fmt_motion_marks,
    fmt_passing,
    fmt_preference,
    fmt_sequence,
    fmt_stnu,
    split_explanation,
    stats_rows,
    table_scope,
)

__all__ = ["render_markdown"]


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def _explanation(plan_class: str, text: str) -> list[str]:
    verdict, key, links = split_explanation(text)
    if not key and 0 < len(links) <= INLINE_LINKS:  # the few human durations that matter: in the sentence
        return [f"**Why {plan_class}:** {verdict}: {_cell('; '.join(links))}.", ""]
    tail = f" \u2014 {'; '.join(key)}." if key else (":" if links else ".")
    out = [f"**Why {plan_class}:** {verdict}{tail}", ""]
    if links:
        what = f"The {len(links)} links of the cycle" if key else f"these {len(links)} links"
        out += [f"<details><summary>{what}</summary>", ""]
        out += [f"{i}. {_cell(link)}" for i, link in enumerate(links, 1)]
        out += ["", "</details>", ""]
    return out


def _link(target: str) -> str:
    if not target:
        return "\u2014"
    return f"[{'graphml' if target.endswith('.graphml') else target}]({target})"


def render_markdown(data: ReportData, figures: dict[str, str]) -> str:
    """The Markdown text; `figures` maps a figure key (``counts``, ``gantt_ID``, ``map_ID``) to its path."""
    out: list[str] = [f"# {data.title}", ""]
    total = sum(n for _, n in data.counts)
    out += [
        f"- **Task:** `{data.task_name}`, digest `{data.digest}`",
        f"- **Seed:** {data.seed}",
        f"- **Deadline:** {'none' if data.deadline is None else f'{data.deadline:g} s'}",
        f"- **Plans:** {total} \u2014 " + ", ".join(f"{c} {n}" for c, n in data.counts),
    ]
    out += [f"- **{k[0].upper()}{k[1:]}:** {v}" for k, v in data.options]
    out += ["", "**What the classes mean.** " + " ".join(f"**{c}**: {text}" for c, text in CLASS_MEANING), "",
            MODEL_ASSUMPTIONS, ""]
    out += [f"**{line}**" if i == 0 else line for i, line in enumerate(data.sensing)]
    if data.sensing:
        out.append("")
    if data.sensing_moves:
        out += ["| Rank | Plan | At delay 0 | Under the sensing | Which constraint breaks |", "|---:|---|---|---|---|"]
        out += [f"| {rank} | `{pid}` | {a} | {b} | {_cell(why)} |" for rank, pid, a, b, why in data.sensing_moves]
        out.append("")
    if "counts" in figures:
        out += [f"![Plans per class]({figures['counts']})", ""]
    for _, reason in data.empty_reasons:
        out += [f"> {reason[0].upper()}{reason[1:]}", ""]

    agents = data.agents
    by_id = {r.plan_id: r for r in data.rows}
    out += ["Contents: [ranked plans](#ranked-plans) \u00b7 featured plans: "
            + " \u00b7 ".join(f"[rank {by_id[pid].rank} ({by_id[pid].plan_class})](#plan-{pid})"
                               for pid in data.featured), ""]
    out += ["## Ranked plans", "",
            f"Allocation: {allocation_legend(data)}. Makespan: earliest \u2013 worst case. "
            f"Idle: {' / '.join(agents)}, in the earliest schedule (waiting counts as idle). "
            "Motion: \u21b7 robot travels on a detour, \u21c4 passing orders the STNU carries. "
            + (f"{PREFERENCE_HEADER}: {PREFERENCE_MEANING} " if data.preferences
               else "") +
            "STNU: timepoints / requirement links / contingent links.", ""]
    if data.truncated:
        out += [f"**{table_scope(data)}**", ""]
    header = (["Rank", "Plan", "Class", "Allocation"] + [f"{a} sequence" for a in agents]
              + ["Makespan (s)", f"Idle {' / '.join(agents)} (s)", "Motion"]
              + ([PREFERENCE_HEADER] if data.preferences else []) + ["STNU", "Network"])
    out += ["| " + " | ".join(header) + " |", "|" + "|".join("---:" if h == "Rank" else "---" for h in header) + "|"]
    for r in data.rows:
        plan = f"[`{r.plan_id}`](#plan-{r.plan_id})" if r.featured else f"`{r.plan_id}`"
        seqs = dict(r.sequences)
        cells = ([str(r.rank), plan, r.plan_class, f"`{r.allocation}`"]
                 + [fmt_sequence(seqs.get(a, ())) for a in agents]
                 + [fmt_makespan(r.makespan), fmt_idle(r.idle), fmt_motion_marks(r)]
                 + ([fmt_preference(r.preference)] if data.preferences else [])
                 + [fmt_stnu(r.stnu_size),
                    _link(r.stnu_link)])
        out.append("| " + " | ".join(_cell(c) for c in cells) + " |")
    out.append("")
    if data.truncated:
        out += ["## All plans", "", f"Makespans of all {data.total:,} plans per class.", "",
                "| " + " | ".join(STATS_HEADER) + " |", "|" + "|".join("---" for _ in STATS_HEADER) + "|"]
        out += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in stats_rows(data)]
        out.append("")
        if "makespans" in figures:
            out += [f"![Worst-case makespans of all plans per class]({figures['makespans']})", ""]

    if data.separation:
        out += ["## What the protective separation costs", "",
                "Each plan compiled with the fixed safety margin and with the protective separation (ISO/TS "
                "15066); plans per class with the margin: " + ", ".join(f"{c} {n}" for c, n in data.margin_counts)
                + ".", "", "| " + " | ".join(COST_HEADER) + " |",
                "|" + "|".join("---:" if h == "Rank" else "---" for h in COST_HEADER) + "|"]
        out += ["| " + " | ".join(_cell(c) for c in cost_cells(r)) + " |" for r in data.separation]
        out.append("")
    rows = {r.plan_id: r for r in data.rows}
    notes = dict(data.notes)
    explanations = dict(data.explanations)
    meetings = dict(data.meetings)
    out += ["## Featured plans", "", "The three best plans and the best plan of each class.", ""]
    for pid in data.featured:
        r = rows[pid]
        seqs = dict(r.sequences)
        out += [f'<a id="plan-{pid}"></a>', "", f"### Rank {r.rank}: plan `{pid}` \u2014 {r.plan_class}", ""]
        idle = ", ".join(f"{a} {s:.1f} s" for a, s in r.idle) or "\u2014"
        out += [f"- **Allocation:** `{r.allocation}`"]
        out += [f"- **{a}:** {fmt_sequence(seqs.get(a, ()))}" for a in agents]
        out += [f"- **Makespan:** {fmt_makespan(r.makespan)} s; **idle:** {idle}",
                "- **STNU:** " + (f"[{r.stnu_link}]({r.stnu_link}) " if r.stnu_link else "not written ")
                + f"({fmt_stnu(r.stnu_size)})", ""]
        if explanations.get(pid):
            out += _explanation(r.plan_class, explanations[pid])
        if f"gantt_{pid}" in figures:
            out += [f"![Gantt chart of plan {pid}, earliest schedule]({figures[f'gantt_{pid}']})", ""]
            if f"gantt_worst_{pid}" in figures:
                out += [f"![Gantt chart of plan {pid}, worst case]({figures[f'gantt_worst_{pid}']})", ""]
        else:
            out += ["*No schedule: the co-workers would block each other, or the durations cannot fit "
                    "together even at their shortest.*", ""]
        if f"map_{pid}" in figures:
            out += [f"![Routes of plan {pid}]({figures[f'map_{pid}']})", ""]
        detours, passing = notes.get(pid, ((), ()))
        if detours:
            out += ["**Detours:**", ""] + [f"- {fmt_detour(d)}" for d in detours] + [""]
        if passing:
            out += ["**Waiting for the co-worker** (passing orders that hold an agent back in the earliest "
                    "schedule):", ""] + [f"- {fmt_passing(p)}" for p in passing] + [""]
        if not detours and not passing:
            out += ["No interference: neither agent waits for the other to pass, and no detour is taken.", ""]
        if meetings.get(pid):
            out += ["**Where the people may meet** (they give way to each other as people do: no order is "
                    "planned there):", ""] + [f"- {m}" for m in meetings[pid]] + [""]
    return "\n".join(out).rstrip("\n") + "\n"
