// hrc console page: plain JavaScript, no library. Talks to the server over one websocket (/ws):
// receives "setup" once per connection, then "state" after every change, and "reply" to its own messages.
// A team (issue 37): "?person=ID" makes this page that person's buttons; without it, the shared view.
"use strict";
(function () {
  const SVGNS = "http://www.w3.org/2000/svg";
  const $ = (id) => document.getElementById(id);
  const C = {                      // what the tests and the curious may read: window.hrcConsole
    ws: null, setup: null, state: null, receivedAt: 0, nextId: 1, pending: new Map(),
    stats: { pressToReply: [], pressToState: [], reconnects: 0, errors: [] }, connected: false,
    person: new URLSearchParams(location.search).get("person"),
  };
  window.hrcConsole = C;
  C.runNow = () => runNow();
  let backoff = 250;

  // ---- the connection -------------------------------------------------------------------------
  function connect() {
    const ws = new WebSocket((location.protocol === "https:" ? "wss://" : "ws://") + location.host + "/ws" +
                             (C.person ? "?person=" + encodeURIComponent(C.person) : ""));
    C.ws = ws;
    ws.onopen = () => { backoff = 250; };
    ws.onmessage = (ev) => {
      let msg;
      try { msg = JSON.parse(ev.data); } catch (e) { showError("the server sent something unreadable"); return; }
      if (msg.type === "setup") { C.setup = msg; C.connected = true; drawSetup(); }
      else if (msg.type === "state") { onState(msg); }
      else if (msg.type === "reply") { onReply(msg); }
    };
    ws.onclose = () => {
      if (C.ws !== ws) return;
      C.connected = false; C.pending.clear();
      setLink(false, "connection lost, reconnecting…");
      drawButtons();
      C.stats.reconnects += 1;
      // refused for want of the run's secret (a console restarted with a new one): say so, keep trying
      fetch("/state", { cache: "no-store" }).then((r) => {
        if (r.status === 401) setLink(false, "not authorized: open the address `hrc console` printed, with its token");
      }).catch(() => {});
      setTimeout(connect, backoff);
      backoff = Math.min(backoff * 2, 4000);
    };
  }

  function send(msg) {
    if (!C.connected || !C.ws || C.ws.readyState !== WebSocket.OPEN) { showError("not connected: wait until the page reconnects"); return; }
    msg.id = C.nextId++;
    msg.hseq = C.state ? mine().hseq : -1;
    C.pending.set(msg.id, { at: performance.now(), hseq: msg.hseq });
    C.ws.send(JSON.stringify(msg));
    drawButtons();
  }

  function onReply(msg) {
    const p = C.pending.get(msg.id);
    if (p) {
      C.pending.delete(msg.id);
      if (msg.ok) { p.replied = performance.now(); C.stats.pressToReply.push(p.replied - p.at); C.waitState = p; }
    }
    if (!msg.ok) showError(msg.error);
    drawButtons();
  }

  function onState(s) {
    C.state = s; C.receivedAt = performance.now();
    setLink(true, s.robot_link === "simulated" ? "connected · robot simulated" :
                  s.robot_link === "connected" ? "connected · robot connected" : "connected · no robot");
    drawState();
    if (C.waitState && mine().hseq > C.waitState.hseq) {  // the press is now on screen
      C.stats.pressToState.push(performance.now() - C.waitState.at);
      C.waitState = null;
    }
    drawStats();
  }

  // ---- whose page: one person and one robot, or a team's person (issue 37), or a team's shared view
  const team = () => !!(C.setup && C.setup.team);
  function mine() {
    const s = C.state, d = s.decision;
    if (!s.persons) return { options: s.options, under_way: s.under_way, undo: s.undo, hseq: s.hseq, hint: d.human,
                             ahead: d.ahead, away: d.human_away, presses: true };
    const p = C.person ? s.persons[C.person] : null;
    if (!p) return { options: [], under_way: [], undo: null, hseq: -1, hint: null, ahead: null, away: false, presses: false };
    return { options: p.options, under_way: p.under_way, undo: p.undo, hseq: p.hseq, hint: (d.people || {})[C.person] || null,
             ahead: (d.ahead || {})[C.person] || null, away: (d.away || []).includes(C.person), presses: true,
             detected: p.detected };
  }
  // one colour per agent, kept across the Gantt chart and the map
  const PALETTE = ["#d9731a", "#1f6fb2", "#2e9e4f", "#8e44ad", "#c0392b", "#138d90", "#7f6a00"];
  function color(agent) {
    if (!team()) return { human: "#d9731a", robot: "#1f6fb2" }[agent] || "#333";
    const i = Object.keys(C.setup.map.agents).indexOf(agent);
    return i < 0 ? "#333" : PALETTE[i % PALETTE.length];
  }
  const isRobot = (agent) => { const a = C.setup.map.agents[agent]; return a ? a.kind === "robot" : agent === "robot"; };

  // ---- time -----------------------------------------------------------------------------------
  function runNow() {
    if (!C.state) return 0;
    if (C.state.finished) return C.state.now;
    return C.state.now + (performance.now() - C.receivedAt) / 1000 * (C.setup ? C.setup.speed : 1);
  }
  const fmt = (t) => (t === null || t === undefined) ? "∞" : t.toFixed(1);

  // ---- drawing --------------------------------------------------------------------------------
  function el(tag, attrs, text) {
    const e = tag.startsWith("svg:") ? document.createElementNS(SVGNS, tag.slice(4)) : document.createElement(tag);
    for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
    if (text !== undefined) e.textContent = text;
    return e;
  }
  function setLink(ok, text) { const l = $("link"); l.textContent = text; l.className = "link " + (ok ? "ok" : "bad"); }
  function showError(text) {
    C.stats.errors.push(text);
    if (C.stats.errors.length > 100) C.stats.errors.shift();  // the last hundred: a flood must not grow the page
    $("error-text").textContent = text; $("error").hidden = false;
  }
  function where(action, phase) {
    const a = C.setup && C.setup.task.actions[action];
    return a && a.phases[phase] ? a.phases[phase] : "?";
  }
  const cap = (s) => s.charAt(0).toUpperCase() + s.slice(1);
  function optionLabel(o) {
    const what = cap(o.phase) + " " + o.action, at = where(o.action, o.phase);
    switch (o.event) {
      case "depart": return ["Go to " + at, "for: " + what];
      case "arrive": return ["I'm at " + at, "for: " + what];
      case "park": return ["Waiting aside", what];
      case "unpark": return ["Going on", what];
      case "start": return [what, "start now, at " + at];
      case "end": return ["Done: " + what, "finished at " + at];
      default: return [o.event + " " + what, ""];
    }
  }

  function drawSetup() {
    $("task-name").textContent = "hrc console · " + C.setup.task.name + (team() ? (C.person ? " · " + C.person + "'s page" : " · shared view") : "");
    if (team()) $("person-title").textContent = C.person ? "You (" + C.person + ")" : "People";
    if (team()) { $("robot-title").textContent = "Robots next"; $("robot-step").hidden = true; }
    $("speed").textContent = C.setup.speed !== 1 ? "×" + C.setup.speed : "";
  }

  function drawButtons() {
    const box = $("buttons"), s = C.state;
    box.textContent = "";
    const busy = !C.connected || C.pending.size > 0 || !s || s.finished;
    if (!s) return;
    const me = mine();
    // "done" first: the phase under way
    const opts = me.options.slice().sort((a, b) => (a.event === "end" ? 0 : 1) - (b.event === "end" ? 0 : 1));
    for (const o of opts) {
      const [big, small] = optionLabel(o);
      const h = me.hint, hinted = h && h.action === o.action && h.phase === o.phase && h.event === o.event;
      const b = el("button", { type: "button", class: "act" + (o.event === "end" ? " done" : "") + (hinted ? " hint" : ""),
                               "data-action": o.action, "data-phase": o.phase, "data-event": o.event });
      b.append(document.createTextNode(big), el("small", {}, small));
      b.disabled = busy;
      b.addEventListener("click", () => send({ type: "press", action: o.action, phase: o.phase, event: o.event }));
      box.append(b);
    }
    if (!opts.length) box.append(el("div", { class: "none" }, s.finished ? "All done." : !me.presses ?
      "The shared view: each person presses on their own page." : "Nothing for you to start now."));
    const away = me.away;
    $("away").hidden = !!away || !me.presses; $("back").hidden = !away || !me.presses;
    $("away").disabled = $("back").disabled = busy;
    $("undo").disabled = busy;
  }

  function drawState() {
    const s = C.state, d = s.decision;
    $("finished").hidden = !s.finished;
    $("log-error").hidden = !s.log_error;  // the server refuses everything until its log can be written
    $("log-error-text").textContent = s.log_error || "";
    // counts per class
    const counts = $("counts"); counts.textContent = "";
    for (const k of ["DC", "consistent", "inconsistent"]) {
      const c = el("span", { class: "count c-" + k, "data-class": k }); c.append(el("small", {}, k), document.createTextNode(String(d.candidates ? d.candidates[k] : 0)));
      counts.append(c);
    }
    // the person: what they are doing (a team's shared view: every person's)
    const doing = $("doing"); doing.textContent = "";
    const me = mine();
    if (me.presses) drawDoing(doing, me, "You", "the robot takes what you have not started.");
    else for (const p of Object.keys(s.persons || {})) {
      const q = s.persons[p];
      drawDoing(doing, { under_way: q.under_way, hint: (d.people || {})[p] || null, ahead: (d.ahead || {})[p] || null,
                         away: (d.away || []).includes(p), detected: q.detected }, p, "the others take what " + p + " has not started.", p);
    }
    drawButtons();
    if (team()) drawRobots(s, d);
    // the robot
    const r = d.robot;
    $("robot-step").textContent = d.stopped ? "STOPPED (no feasible plan)" : !r ? (s.finished ? "finished" : "nothing left to do")
      : r.wait_for ? "wait for " + r.wait_for : r.event + " · " + r.phase + " " + r.action;
    $("robot-step").setAttribute("data-decision", JSON.stringify(r));
    $("robot-window").textContent = r && r.action ? "window " + fmt(r.earliest) + " – " + fmt(r.latest) + " s" : "";
    const seqs = !s.best ? "" : team() ? Object.keys(C.setup.map.agents).map((a) => " · " + a + ": " + (s.best.sequences[a] || []).join(" ")).join("")
      : " · human: " + (s.best.sequences.human || []).join(" ") + " · robot: " + (s.best.sequences.robot || []).join(" ");
    $("plan-line").textContent = d.plan ? "best plan " + d.plan + " (" + d.class + ")" +
      (s.best && s.best.makespan !== null ? ", makespan " + fmt(s.best.makespan) + " s" : "") + seqs : "no plan";
    drawGantt(); drawMap(); drawLog();
  }

  function drawDoing(box, me, who, awayText, tag) {
    const line = (cls, text) => { const e = el("div", { class: cls }, (tag ? tag + ": " : "") + text); if (tag) { e.dataset.person = tag; e.style.color = color(tag); } box.append(e); };
    if (me.away) box.append(el("span", { class: "away" }, (tag ? tag + " is" : "You are") + " away: " + awayText));
    else if (me.under_way.length) line("under-way", "Under way: " + me.under_way.map(([a, p]) => cap(p) + " " + a).join(", "));
    const h = me.hint;  // the dispatcher's hint: the person's next step in the best plan, or what to wait for
    if (h && h.wait_for) line("hint-line wait", "Please wait for the " + h.wait_for.replace(/\./g, " "));
    else if (h && h.action) line("hint-line", "Suggested: " + optionLabel(h).join(" · ") +
      (h.latest !== null ? " (by " + fmt(h.latest) + " s)" : ""));
    const ahead = me.ahead;  // while a walk or a manipulation is under way: the instruction for the step after it
    if (!h && ahead) {
      const words = (name) => name.split(".").slice(1).reverse().join(" ");
      line("hint-line ahead", "Next, after " + words(ahead.after) + ": " +
        (ahead.wait_for ? "wait for the " + ahead.wait_for.replace(/\./g, " ") +
          (ahead.gap > 0 ? " and " + fmt(ahead.gap) + " s more" : "") + " before " + (tag ? "they " : "you ") + words(ahead.next)
          : words(ahead.next)));
    }
    // with the motion detector (a team's person): the last events their own detector gave, newest first
    const seen = (me.detected || []).filter((e) => e.event !== "undo").slice(-4).reverse();
    if (seen.length) line("detected", "Seen by the tracker: " + seen.map((e) => `${e.event} ${e.action}.${e.phase} @${fmt(e.t)}`).join(", "));
  }

  // A team's robots (issue 37): one row per robot, its next step, window and link.
  function stepText(r, finished) {
    return !r ? (finished ? "finished" : "nothing left to do") : r.wait_for ? "wait for " + r.wait_for : r.event + " · " + r.phase + " " + r.action;
  }
  function drawRobots(s, d) {
    const box = $("robots"); box.textContent = "";
    for (const [id, r] of Object.entries(d.robots || {})) {
      const row = el("div", { class: "robot-row", "data-robot": id, "data-decision": JSON.stringify(r) });
      const name = el("b", {}, id); name.style.color = color(id);
      row.append(name, document.createTextNode(" " + (d.stopped ? "STOPPED" : stepText(r, s.finished))),
                 el("span", { class: "robot-when" }),
                 el("small", {}, (r && r.action ? " · window " + fmt(r.earliest) + " – " + fmt(r.latest) + " s" : "") +
                                  " · " + ((s.robot_links || {})[id] || "none")));
      box.append(row);
    }
  }
  function countdown(r, now) {
    if (!r || !r.action) return "";
    return now < r.earliest ? "in " + (r.earliest - now).toFixed(1) + " s" :
           (r.latest === null || now <= r.latest) ? "now" + (r.latest !== null ? " (" + (r.latest - now).toFixed(1) + " s left)" : "") : "late";
  }

  function tickDraw() {
    if (C.state) {
      const now = runNow();
      $("clock").textContent = fmt(now) + " s";
      $("robot-countdown").textContent = team() ? "" : countdown(C.state.decision.robot, now);
      for (const row of document.querySelectorAll("#robots .robot-row")) {
        const when = row.querySelector(".robot-when");
        if (when) when.textContent = " " + countdown((C.state.decision.robots || {})[row.dataset.robot], now);
      }
      const u = mine().undo, ub = $("undo");
      if (u && now <= u.until && !C.state.finished) { ub.hidden = false; ub.textContent = "Undo " + u.what + " (" + Math.max(0, u.until - now).toFixed(0) + " s)"; }
      else ub.hidden = true;
      const line = document.getElementById("now-line");
      if (line && C.gx) { const x = C.gx(now); line.setAttribute("x1", x); line.setAttribute("x2", x); }
    }
    requestAnimationFrame(tickDraw);
  }

  // Gantt: one row per agent, the plan's bars above (outlined), what happened below (filled).
  function drawGantt() {
    const svg = $("gantt"), s = C.state, g = s.gantt;
    svg.textContent = "";
    const agents = team() ? Object.keys(C.setup.map.agents) : ["human", "robot"];
    const W = 800, rowH = 56, top = 22, left = 64, H = top + agents.length * rowH + 26;
    svg.setAttribute("viewBox", `0 0 ${W} ${H}`);
    const deadline = C.setup.task.deadline;
    let tmax = Math.max(deadline || 0, s.now);
    for (const b of g.planned.concat(g.actual)) tmax = Math.max(tmax, b.to);
    tmax = Math.ceil((tmax + 5) / 10) * 10;
    const x = (t) => left + (W - left - 10) * t / tmax;
    C.gx = x;
    for (let t = 0; t <= tmax; t += 10) {
      svg.append(el("svg:line", { x1: x(t), x2: x(t), y1: top - 4, y2: H - 20, stroke: "#e2e2e2" }));
      svg.append(el("svg:text", { x: x(t), y: H - 6, "font-size": 12, "text-anchor": "middle", fill: "#666" }, String(t)));
    }
    agents.forEach((a, i) => svg.append(el("svg:text", { x: 6, y: top + i * rowH + rowH / 2 + 5, "font-size": 15, "font-weight": 700, fill: color(a), class: "gantt-row", "data-agent": a }, a)));
    const fill = { travel: "#9aa7b4", wait: "#e6c229", work: null };
    const draw = (b, actual) => {
      const i = agents.indexOf(b.agent); if (i < 0) return;
      const y = top + i * rowH + (actual ? rowH / 2 : 2), h = rowH / 2 - 6;
      const col = fill[b.kind] || color(b.agent);
      const w = Math.max(1.5, x(b.to) - x(b.from));
      const r = el("svg:rect", { x: x(b.from), y, width: w, height: h, rx: 3,
        fill: actual ? col : "none", stroke: col, "stroke-width": actual ? 0 : 2, "stroke-dasharray": actual ? "" : (b.kind === "work" ? "" : "4 3"),
        class: (actual ? "bar-actual" : "bar-planned") + " bar-" + b.kind, "data-agent": b.agent });
      r.append(el("svg:title", {}, `${b.agent} ${b.kind} ${b.action}.${b.phase}: ${fmt(b.from)} – ${fmt(b.to)} s`));
      svg.append(r);
      if (b.kind === "work" && w > 34) svg.append(el("svg:text", { x: x(b.from) + 3, y: y + h - 7, "font-size": 11, fill: actual ? "#fff" : "#333" }, b.action.replace("cube", "c").replace("triangle", "tri") + (b.phase === "put" ? "↓" : "↑")));
    };
    g.planned.forEach((b) => draw(b, false));
    g.actual.forEach((b) => draw(b, true));
    if (deadline) {
      svg.append(el("svg:line", { x1: x(deadline), x2: x(deadline), y1: top - 12, y2: H - 20, stroke: "#000", "stroke-width": 2, "stroke-dasharray": "6 4" }));
      svg.append(el("svg:text", { x: x(deadline) + 3, y: top - 10, "font-size": 11 }, "deadline " + deadline + " s"));
    }
    svg.append(el("svg:line", { id: "now-line", x1: x(runNow()), x2: x(runNow()), y1: top - 12, y2: H - 20, stroke: "#d00", "stroke-width": 2 }));
  }

  // The map: obstacles, locations, both agents' routes in the best plan, where each agent is.
  function drawMap() {
    const svg = $("map"), m = C.setup.map, s = C.state;
    svg.textContent = "";
    const [x0, y0, x1, y1] = m.bounds, pad = 0.4;
    svg.setAttribute("viewBox", `${x0 - pad} ${-(y1 + pad)} ${x1 - x0 + 2 * pad} ${y1 - y0 + 2 * pad}`);
    const P = (p) => `${p[0]},${-p[1]}`;
    svg.append(el("svg:rect", { x: x0, y: -y1, width: x1 - x0, height: y1 - y0, fill: "#fff", stroke: "#444", "stroke-width": 0.05 }));
    for (const o of m.obstacles) svg.append(el("svg:polygon", { points: o.points.map(P).join(" "), fill: "#bbb", stroke: "#888", "stroke-width": 0.02 }));
    for (const [agent, legs] of Object.entries(s.routes)) {
      legs.forEach((leg) => {
        if (leg.points.length < 2) return;
        const pl = el("svg:polyline", { points: leg.points.map(P).join(" "), fill: "none", stroke: color(agent),
          "stroke-width": 0.07, "stroke-dasharray": isRobot(agent) ? "0.25 0.12" : "", "stroke-linejoin": "round", "stroke-opacity": 0.8, class: "route route-" + agent });
        pl.append(el("svg:title", {}, `${agent}: ${leg.from} → ${leg.to} for ${leg.action}.${leg.phase}` + (leg.detour ? ` (detour round ${leg.detour})` : "")));
        svg.append(pl);
      });
    }
    for (const [id, p] of Object.entries(m.locations)) {
      svg.append(el("svg:circle", { cx: p[0], cy: -p[1], r: 0.09, fill: "#333" }));
      svg.append(el("svg:text", { x: p[0] + 0.14, y: -p[1] - 0.1, "font-size": 0.32, fill: "#222" }, id));
    }
    const tracked = (agent) => s.persons ? (s.persons[agent] || {}).tracked : s.tracked;
    for (const [agent, a] of Object.entries(m.agents)) {
      if (a.kind === "human" && tracked(agent)) continue;  // the tracker says where the person is
      const at = s.where && s.where[agent] ? s.where[agent] : a.start, p = m.locations[at];
      if (!p) continue;
      svg.append(el("svg:circle", { cx: p[0], cy: -p[1], r: a.radius, fill: color(agent), "fill-opacity": 0.35, stroke: color(agent), "stroke-width": 0.05, class: "agent", "data-agent": agent }));
    }
    // The motion detector (hrc console --detect motion): the person's tracked position and its belief.
    // A team's (issue 37): each person's own, from their own detector.
    const people = s.persons ? Object.keys(s.persons).map((p) => [p, s.persons[p]])
      : s.tracked ? [[(Object.entries(m.agents).find(([, a]) => a.kind === "human") || ["human"])[0], s]] : [];
    for (const [agent, q] of people) {
      const at = q.tracked, b = q.belief || {};
      if (!at) continue;
      const r = m.agents[agent] ? m.agents[agent].radius : 0.3, col = color(s.persons ? agent : "human"), one = !s.persons;
      const dot = el("svg:circle", { id: one ? "tracked" : "tracked-" + agent, class: "tracked", "data-agent": agent, cx: at.x, cy: -at.y, r, fill: col, "fill-opacity": 0.5, stroke: col, "stroke-width": 0.06, "stroke-dasharray": "0.12 0.08" });
      dot.append(el("svg:title", {}, `${one ? "" : agent + " "}tracked at ${fmt(at.t)} s: (${at.x}, ${at.y})`));
      svg.append(dot);
      svg.append(el("svg:text", { id: one ? "belief" : "belief-" + agent, x: at.x + r + 0.1, y: -at.y + 0.12, "font-size": 0.34, fill: "#222", stroke: "#fff", "stroke-width": 0.06, "paint-order": "stroke" }, (one ? "" : agent + ": ") + beliefText(b)));
    }
  }

  function beliefText(b) {
    if (!b || !b.doing) return "";
    const leg = b.action ? ` ${b.action}.${b.phase}` : "";
    const p = b.p !== undefined && b.p < 1 ? ` (${Math.round(100 * b.p)} %)` : "";
    return `${b.doing}${leg}${p}`;
  }

  function describeIn(m) {
    if (m.event === "tick") return "tick";
    if (m.event === "position") return `${team() && m.agent ? m.agent + " " : ""}position (${m.x.toFixed(2)}, ${m.y.toFixed(2)})`;
    return [m.agent, m.event, m.action, m.phase].filter(Boolean).join(" ");
  }
  function detectedText(o) {  // the events a position's detector gave (a team's: whose detector)
    if (!o.detect || !o.detect.events.length) return "";
    return "detected " + (o.detect.agent ? o.detect.agent + " " : "") + o.detect.events.map((e) => e.event === "undo" ? "undo" : `${e.event} ${e.action}.${e.phase} @${fmt(e.t)}`).join(", ") + " · ";
  }
  function describeOut(o) {
    if (!o.ok) return "refused: " + o.error;
    if (o.robots) return detectedText(o) + Object.entries(o.robots).map(([id, r]) => !r ? id + ": nothing" : r.wait_for ? id + " waits for " + r.wait_for
      : `${id} ${r.event} ${r.action}.${r.phase} in [${fmt(r.earliest)}, ${fmt(r.latest)}]`).join(" · ") + ` · plan ${o.plan} (${o.class})`;
    const r = o.robot;
    const step = !r ? "robot: nothing" : r.wait_for ? "robot waits for " + r.wait_for : `robot ${r.event} ${r.action}.${r.phase} in [${fmt(r.earliest)}, ${fmt(r.latest)}]`;
    return `${detectedText(o)}${step} · plan ${o.plan} (${o.class})`;
  }
  function drawLog() {
    const s = C.state, body = $("log").querySelector("tbody");
    body.textContent = "";
    $("log-count").textContent = "(" + s.log_total + " messages)";
    let prev = null;
    const rows = [];
    for (const e of s.log) {
      const key = JSON.stringify([e.out.robots || e.out.robot, e.out.plan, e.out.ok]);
      if (e.in.event === "tick" && e.out.ok && key === prev) continue;  // ticks that changed nothing
      if (e.in.event === "position" && e.out.ok && !(e.out.detect && e.out.detect.events.length)) continue;  // nothing detected
      prev = e.out.ok ? key : prev;
      const tr = el("tr", { class: e.out.ok ? "ok" : "refused", "data-n": e.n });
      tr.append(el("td", {}, String(e.n)), el("td", {}, fmt(e.in.t)), el("td", {}, e.source), el("td", {}, describeIn(e.in)), el("td", { class: "decision" }, describeOut(e.out)));
      rows.push(tr);
    }
    rows.reverse().forEach((r) => body.append(r));
  }
  function drawStats() {
    const a = C.stats.pressToState;
    if (!a.length) return;
    const sorted = a.slice().sort((p, q) => p - q), med = sorted[Math.floor(sorted.length / 2)];
    $("stats").textContent = `press → decision on screen: median ${med.toFixed(1)} ms over ${a.length} presses`;
  }

  // ---- the person's other buttons --------------------------------------------------------------
  $("away").addEventListener("click", () => send({ type: "away" }));
  $("back").addEventListener("click", () => send({ type: "back" }));
  $("undo").addEventListener("click", () => send({ type: "undo" }));
  $("error-close").addEventListener("click", () => { $("error").hidden = true; });
  connect();
  requestAnimationFrame(tickDraw);
})();
