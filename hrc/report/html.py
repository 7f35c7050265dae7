"""``report.html``: the same content as ``report.md``, one self-contained page.

Inline CSS only: no scripts, fonts or other external resources; images are referenced relatively
(``figures/NAME.png``) so the output folder can be moved or served as is. Every text is escaped.
"""

from __future__ import annotations

from html import escape

from hrc.report.figures import CLASS_COLORS
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

__all__ = ["render_html"]

_CSS = """
body{margin:0;background:#f6f7f9;color:#1d2330;font:15px/1.5 -apple-system,"Segoe UI",Roboto,"Helvetica Neue",
Arial,sans-serif}
main{max-width:1240px;margin:0 auto;padding:28px 32px 60px}
h1{font-size:26px;margin:0 0 4px}h2{font-size:20px;margin:36px 0 10px;border-bottom:1px solid #dde1e7;
padding-bottom:4px}h3{font-size:17px;margin:0 0 8px}
code{font:13px/1.4 "SFMono-Regular",Menlo,Consolas,monospace;background:#eef0f4;padding:1px 4px;border-radius:3px}
a{color:#1f5fa8;text-decoration:none}a:hover{text-decoration:underline}
.meta{display:grid;grid-template-columns:max-content 1fr;gap:2px 14px;margin:12px 0}
.meta dt{color:#5b6372}.meta dd{margin:0}
.summary{display:flex;gap:28px;align-items:center;flex-wrap:wrap}
.cards{display:flex;gap:12px}.card{background:#fff;border:1px solid #dde1e7;border-radius:8px;padding:10px 18px;
text-align:center;min-width:96px}.card b{display:block;font-size:26px;line-height:1.2}
.note{background:#fff8e1;border-left:4px solid #e0a000;padding:8px 12px;margin:10px 0;border-radius:0 4px 4px 0}
.badge{display:inline-block;padding:1px 9px;border-radius:10px;color:#fff;font-size:12px;font-weight:600;
white-space:nowrap}
.small{color:#5b6372;font-size:13px}
.table-wrap{overflow-x:auto;background:#fff;border:1px solid #dde1e7;border-radius:8px}
table{border-collapse:collapse;width:100%;font-size:13px}
th,td{padding:5px 8px;text-align:left;white-space:nowrap;border-bottom:1px solid #edf0f3}
th{background:#eef0f4;position:sticky;top:0;font-weight:600}
td.seq{white-space:normal;min-width:150px}
td.num{text-align:right;font-variant-numeric:tabular-nums}tr.featured td{background:#f3f8ff}
tbody tr:hover td{background:#fafbfc}
section.plan{background:#fff;border:1px solid #dde1e7;border-radius:8px;padding:18px 22px;margin:18px 0}
.facts{display:grid;grid-template-columns:max-content 1fr;gap:2px 14px;margin:0 0 12px;font-size:14px}
.facts dt{color:#5b6372}.facts dd{margin:0}
.why{background:#fdecea;border-left:4px solid #c62828;padding:8px 12px;margin:8px 0 12px;border-radius:0 4px 4px 0}
.why.consistent{background:#fff8e1;border-color:#e0a000}
.why details{margin-top:4px;font-size:13px}.why summary{cursor:pointer;color:#5b6372}.why ol{margin:4px 0 0}
img{max-width:100%;height:auto;display:block}
.figs{display:grid;grid-template-columns:minmax(0,640px) minmax(0,1fr);gap:18px;align-items:start;margin-top:12px}
ul.motions{margin:4px 0 0;padding-left:18px;font-size:14px}ul.motions ul{padding-left:18px;color:#7a1f1f}
""".strip()


def _featured_ranks(data: ReportData) -> list[tuple[str, int, str]]:
    rows = {r.plan_id: r for r in data.rows}
    return [(pid, rows[pid].rank, rows[pid].plan_class) for pid in data.featured]


def _badge(cls: str) -> str:
    color = CLASS_COLORS.get(cls, "#777777")
    return f'<span class="badge" style="background:{color}">{escape(cls)}</span>'


def _explanation(plan_class: str, text: str) -> str:
    verdict, key, links = split_explanation(text)
    e = escape
    if not key and 0 < len(links) <= INLINE_LINKS:  # the few human durations that matter: in the sentence
        return (f'<div class="why {e(plan_class)}"><b>Why {e(plan_class)}:</b> {e(verdict)}: '
                f'{e("; ".join(links))}.</div>')
    tail = f" \u2014 {e('; '.join(key))}." if key else (":" if links else ".")
    html = f'<div class="why {e(plan_class)}"><b>Why {e(plan_class)}:</b> {e(verdict)}{tail}'
    if links:
        what = f"The {len(links)} links of the cycle" if key else f"these {len(links)} links"
        items = "".join(f"<li>{e(link)}</li>" for link in links)
        html += f"<details><summary>{what}</summary><ol>{items}</ol></details>"
    return html + "</div>"


def _link_cell(target: str) -> str:
    if not target:
        return "<td>\u2014</td>"
    label = "graphml" if target.endswith(".graphml") else target
    return f'<td><a href="{escape(target)}">{escape(label)}</a></td>'


def render_html(data: ReportData, figures: dict[str, str]) -> str:
    """The HTML page; `figures` maps a figure key (``counts``, ``gantt_ID``, ``map_ID``) to its path."""
    e = escape
    agents = data.agents
    total = sum(n for _, n in data.counts)
    out: list[str] = [
        "<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{e(data.title)}</title>", f"<style>\n{_CSS}\n</style>", "</head>", "<body>", "<main>",
        f"<h1>{e(data.title)}</h1>",
        '<dl class="meta">',
        f"<dt>Task</dt><dd><code>{e(data.task_name)}</code></dd>",
        f"<dt>Digest</dt><dd><code>{e(data.digest)}</code></dd>",
        f"<dt>Seed</dt><dd>{data.seed}</dd>",
        f"<dt>Deadline</dt><dd>{'none' if data.deadline is None else f'{data.deadline:g} s'}</dd>",
        f"<dt>Plans</dt><dd>{total}</dd>",
    ]
    out += [f"<dt>{e(k[0].upper() + k[1:])}</dt><dd>{e(v)}</dd>" for k, v in data.options]
    out += [
        "</dl>",
        '<p class="small"><b>What the classes mean.</b> '
        + " ".join(f"{_badge(c)} {e(text)}" for c, text in CLASS_MEANING) + "</p>",
        f'<p class="small">{e(MODEL_ASSUMPTIONS).replace("`", "")}</p>',
        *(f'<p class="small">{e(line)}</p>' for line in data.sensing),
        *(["<table><tr><th>Rank</th><th>Plan</th><th>At delay 0</th><th>Under the sensing</th>"
            "<th>Which constraint breaks</th></tr>"]
          + [f"<tr><td>{rank}</td><td><code>{e(pid)}</code></td><td>{e(a)}</td><td>{e(b)}</td><td>{e(why)}</td></tr>"
             for rank, pid, a, b, why in data.sensing_moves] + ["</table>"] if data.sensing_moves else []),
        '<div class="summary"><div class="cards">',
    ]
    for cls, n in data.counts:
        out.append(f'<div class="card"><b>{n}</b>{_badge(cls)}</div>')
    out.append("</div>")
    if "counts" in figures:
        out.append(f'<img src="{e(figures["counts"])}" alt="Plans per class" width="420" height="240">')
    out.append("</div>")
    for _, reason in data.empty_reasons:
        out.append(f'<p class="note">{e(reason[0].upper() + reason[1:])}</p>')

    jumps = " \u00b7 ".join(f'<a href="#plan-{e(pid)}">rank {rank} ({e(cls)})</a>'
                             for pid, rank, cls in _featured_ranks(data))
    out.append(f'<p class="small">Contents: <a href="#ranked">ranked plans</a> \u00b7 featured plans: {jumps}</p>')
    out += ['<h2 id="ranked">Ranked plans</h2>',
            f'<p class="small">Allocation: {e(allocation_legend(data))}. Makespan: earliest \u2013 worst case. '
            f"Idle: {e(' / '.join(agents))}, in the earliest schedule (waiting counts as idle). "
            "Motion: \u21b7 robot travels on a detour, \u21c4 passing orders the STNU carries. "
            + (f"{PREFERENCE_HEADER}: {PREFERENCE_MEANING} " if data.preferences
               else "") +
            "STNU: timepoints / requirement links / contingent links. Highlighted rows have a section below.</p>"]
    if data.truncated:
        out.append(f'<p class="note">{e(table_scope(data))}</p>')
    out += ['<div class="table-wrap"><table>', "<thead><tr>"]
    header = (["Rank", "Plan", "Class", "Allocation"] + [f"{a} sequence" for a in agents]
              + ["Makespan (s)", f"Idle {' / '.join(agents)} (s)", "Motion"]
              + ([PREFERENCE_HEADER] if data.preferences else []) + ["STNU", "Network"])
    out.append("".join(f"<th>{e(h)}</th>" for h in header) + "</tr></thead>")
    out.append("<tbody>")
    for r in data.rows:
        seqs = dict(r.sequences)
        pid = e(r.plan_id)
        plan = f'<a href="#plan-{pid}"><code>{pid}</code></a>' if r.featured else f"<code>{pid}</code>"
        cells = ([f'<td class="num">{r.rank}</td>', f"<td>{plan}</td>", f"<td>{_badge(r.plan_class)}</td>",
                  f"<td><code>{e(r.allocation)}</code></td>"]
                 + [f'<td class="seq">{e(fmt_sequence(seqs.get(a, ())))}</td>' for a in agents]
                 + [f'<td class="num">{e(fmt_makespan(r.makespan))}</td>',
                    f'<td class="num">{e(fmt_idle(r.idle))}</td>',
                    f"<td>{e(fmt_motion_marks(r))}</td>"]
                 + ([f'<td class="num">{e(fmt_preference(r.preference))}</td>'] if data.preferences else [])
                 + [f'<td class="num">{e(fmt_stnu(r.stnu_size))}</td>',
                    _link_cell(r.stnu_link)])
        out.append(('<tr class="featured">' if r.featured else "<tr>") + "".join(cells) + "</tr>")
    out += ["</tbody>", "</table></div>"]
    if data.truncated:
        out += ['<h2 id="all">All plans</h2>', f'<p class="small">Makespans of all {data.total:,} plans per class.</p>',
                '<div class="table-wrap"><table>', "<thead><tr>" + "".join(f"<th>{e(h)}</th>" for h in STATS_HEADER)
                + "</tr></thead>", "<tbody>"]
        out += ["<tr>" + f"<td>{_badge(row[0])}</td>" + "".join(f'<td class="num">{e(c)}</td>' for c in row[1:])
                + "</tr>" for row in stats_rows(data)]
        out += ["</tbody>", "</table></div>"]
        if "makespans" in figures:
            out.append(f'<img src="{e(figures["makespans"])}" alt="Worst-case makespans of all plans per class">')

    if data.separation:
        out += ['<h2 id="separation">What the protective separation costs</h2>',
                '<p class="small">Each plan compiled with the fixed safety margin and with the protective separation '
                "(ISO/TS 15066); plans per class with the margin: "
                + e(", ".join(f"{c} {n}" for c, n in data.margin_counts)) + ".</p>",
                '<div class="table-wrap"><table>', "<thead><tr>" + "".join(f"<th>{e(h)}</th>" for h in COST_HEADER)
                + "</tr></thead>", "<tbody>"]
        out += ["<tr>" + "".join(f"<td>{e(c.strip('`'))}</td>" for c in cost_cells(r)) + "</tr>"
                for r in data.separation]
        out += ["</tbody>", "</table></div>"]
    rows = {r.plan_id: r for r in data.rows}
    notes = dict(data.notes)
    explanations = dict(data.explanations)
    out += ['<h2 id="featured">Featured plans</h2>',
            '<p class="small">The three best plans and the best plan of each class.</p>']
    for plan_id in data.featured:
        r = rows[plan_id]
        pid = e(plan_id)
        seqs = dict(r.sequences)
        idle = ", ".join(f"{a} {s:.1f} s" for a, s in r.idle) or "\u2014"
        out += [f'<section class="plan" id="plan-{pid}">',
                f"<h3>Rank {r.rank}: plan <code>{pid}</code> {_badge(r.plan_class)}</h3>",
                '<dl class="facts">',
                f"<dt>Allocation</dt><dd><code>{e(r.allocation)}</code></dd>"]
        out += [f"<dt>{e(a)}</dt><dd>{e(fmt_sequence(seqs.get(a, ())))}</dd>" for a in agents]
        out += [f"<dt>Makespan</dt><dd>{e(fmt_makespan(r.makespan))} s (earliest \u2013 worst case)</dd>",
                f"<dt>Idle</dt><dd>{e(idle)}</dd>",
                "<dt>STNU</dt><dd>" + (f'<a href="{e(r.stnu_link)}">{e(r.stnu_link)}</a>' if r.stnu_link
                                       else "not written") + f" ({e(fmt_stnu(r.stnu_size))})</dd>",
                "</dl>"]
        if explanations.get(plan_id):
            out.append(_explanation(r.plan_class, explanations[plan_id]))
        gantt = figures.get(f"gantt_{plan_id}")
        if gantt:
            out.append(f'<img src="{e(gantt)}" alt="Gantt chart of plan {pid}, earliest schedule">')
            worst = figures.get(f"gantt_worst_{plan_id}")
            if worst:
                out.append(f'<img src="{e(worst)}" alt="Gantt chart of plan {pid}, worst case">')
        else:
            out.append('<p class="small">No schedule: the co-workers would block each other, or the durations '
                       "cannot fit together even at their shortest.</p>")
        out.append('<div class="figs">')
        themap = figures.get(f"map_{plan_id}")
        out.append(f'<img src="{e(themap)}" alt="Routes of plan {pid}">' if themap else "<div></div>")
        out.append("<div>")
        detours, passing = notes.get(plan_id, ((), ()))
        if detours:
            out += ["<b>Detours</b>", '<ul class="motions">']
            out += [f"<li>{e(fmt_detour(d))}</li>" for d in detours]
            out.append("</ul>")
        if passing:
            out += ["<b>Waiting for the co-worker</b>",
                    '<p class="small">Passing orders that hold an agent back in the earliest schedule.</p>',
                    '<ul class="motions">']
            out += [f"<li>{e(fmt_passing(p))}</li>" for p in passing]
            out.append("</ul>")
        if not detours and not passing:
            out.append('<p class="small">No interference: neither agent waits for the other to pass, and no '
                       "detour is taken.</p>")
        if dict(data.meetings).get(plan_id):
            out += ["<b>Where the people may meet</b>",
                    '<p class="small">They give way to each other as people do: no order is planned there.</p>',
                    '<ul class="motions">'] + [f"<li>{e(m)}</li>" for m in dict(data.meetings)[plan_id]] + ["</ul>"]
        out += ["</div>", "</div>", "</section>"]
    out += ["</main>", "</body>", "</html>"]
    return "\n".join(out) + "\n"
