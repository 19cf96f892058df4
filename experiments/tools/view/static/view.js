// dfrl live view: applies the run's events (server-sent, see server.py) to a model and draws
// it with plain SVG and canvas. No library, nothing fetched from outside.
"use strict";
(function () {
  const NS = "http://www.w3.org/2000/svg";
  const COLORS = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#8c564b",
                  "#e377c2", "#7f7f7f", "#bcbd22"];
  const AGENT_COLORS = ["#c2185b", "#1565c0", "#ef6c00", "#2e7d32"];
  const LISTED = new Set(["robot", "agent", "round", "skip", "method", "error", "aborted",
    "control", "resurrected", "superseded", "finished", "robot_state", "run_end", "join"]);
  const MAX_LIST = 200;            // event list entries kept in the page
  // The page's cost is the browser redrawing it, so it redraws little: one frame at most
  // every RENDER_MS while following a live run (requestAnimationFrame, so nothing while the
  // tab is hidden), the curves and arenas at most every CHART_MS, only what changed, and at
  // most MAX_PTS points per curve. Nothing on the page animates by itself.
  const RENDER_MS = 400;
  const CHART_MS = 2000;
  const MAX_PTS = 400;
  const QUEUE = 4;                // hops waiting to be shown, one per frame (older dropped)
  const CURVES = [["chart-q", "q"], ["chart-cr", "cr"], ["chart-ev", "ev"]];

  const all = [];                 // every event received, by seq
  let S = fresh();                // the model at the replay position
  let applied = 0;                // events applied to S
  let follow = true;              // apply new events as they come
  let listed = 0;                 // entries of S.list already in the page's list
  const stats = { received: 0, applyMs: 0, renderMs: 0, renders: 0, firstPaintMs: null,
                  connected: false };
  window.dfrlView = { stats, model: () => S };

  function fresh() {
    return { run: null, robots: new Map(), order: [], agents: new Map(), t0: null,
             ended: false, list: [], curves: 0, arenas: 0 };
  }
  function robot(id) {
    let r = S.robots.get(id);
    if (!r) {
      r = { id, host: "", port: "", arena: "", algo: "", state: "learning", q: [], cr: [], ev: [],
            ext: { q: [0, 1e-9], cr: [0, 1e-9], ev: [0, 1e-9] }, shares: [], pose: null,
            spec: null, iteration: 0, color: COLORS[S.order.length % COLORS.length] };
      S.robots.set(id, r); S.order.push(id);
    }
    return r;
  }
  function agent(name) {
    let a = S.agents.get(name);
    if (!a) {
      a = { name, algo: "", method: "", rounds: 0, round: 0, lastMs: null, at: null,
            phase: "rest", prev: null, moves: 0, itinerary: [], queue: [], shown: null,
            kind: "chain", clones: new Map(), cloneRound: null, cloneMarks: null,
            color: AGENT_COLORS[S.agents.size % AGENT_COLORS.length] };
      S.agents.set(name, a);
    }
    return a;
  }
  function names(list) {
    return list.length <= 8 ? list.join(",") : `${list.slice(0, 3).join(",")},…,${list[list.length - 1]} (${list.length})`;
  }
  function note(ev, text, fault) {
    S.list.push({ seq: ev.seq, kind: ev.kind, t: ev.t, text, fault: !!fault });
    if (S.list.length > 2 * MAX_LIST) {
      const cut = S.list.length - MAX_LIST;
      S.list.splice(0, cut); listed = Math.max(0, listed - cut);
    }
  }
  function point(r, key, it, v) {
    // a curve only grows to the right (a point at or before its last one is dropped: the
    // status of a remote robot before its files arrive, then the files)
    const pts = r[key];
    if (pts.length && it <= pts[pts.length - 1][0]) return;
    pts.push([it, v]);
    const e = r.ext[key];
    if (v < e[0]) e[0] = v;
    if (v > e[1]) e[1] = v;
  }

  // -- the model ------------------------------------------------------------------------
  function apply(ev) {
    switch (ev.kind) {
      case "run":
        S.run = ev; S.t0 = ev.t; break;
      case "robot": {
        const r = robot(ev.robot);
        Object.assign(r, { host: ev.host, port: ev.port, arena: ev.arena, algo: ev.algo,
                           robot_host: ev.robot_host, joined: ev.joined });
        note(ev, `${ev.joined ? "joined" : "robot up"}: ${ev.robot} ${ev.host}:${ev.port} ` +
                 `arena ${ev.arena}, ${ev.algo}`);
        break;
      }
      case "arena": robot(ev.robot).spec = ev; S.arenas++; break;
      case "agent": {
        const a = agent(ev.agent);
        Object.assign(a, { algo: ev.algo, method: ev.method, rounds: ev.rounds,
                           itinerary: ev.itinerary || [], kind: ev.itinerary_kind || "chain" });
        if (!a.at && a.itinerary.length) a.at = a.itinerary[0];
        note(ev, `agent ${ev.agent} (${ev.method}, ${ev.rounds} rounds): ` +
                 ((ev.itinerary || []).length <= 8 ? ev.itinerary.join(" → ") : names(ev.itinerary)));
        break;
      }
      case "hop": {
        const a = agent(ev.agent);
        if (ev.clone) {
          // a tree's copy at that robot: the agent stays at its root; the copies of the
          // round being shown stay drawn until the next round's first copy
          if (ev.round !== a.cloneRound) { a.clones.clear(); a.cloneRound = ev.round; }
          a.clones.set(ev.robot, ev.phase); a.moves++;
          a.round = Math.max(a.round, ev.round - 1); a.current = ev.round;
          break;
        }
        a.prev = a.at; a.at = ev.robot; a.phase = ev.phase; a.moves++;
        a.queue.push({ at: a.at, prev: a.prev, phase: a.phase });
        a.round = Math.max(a.round, ev.round - 1);
        a.current = ev.round;
        break;
      }
      case "round": {
        const a = agent(ev.agent);
        a.round = Math.max(a.round, ev.round); a.lastMs = ev.duration_ms; a.method = ev.method;
        a.phase = "rest"; a.prev = a.at; a.at = ev.visited.length ? ev.visited[0] : a.at;
        a.queue.push({ at: a.at, prev: a.prev, phase: a.phase });
        note(ev, `${ev.agent} round ${ev.round}: ${ev.method}, ${ev.duration_ms.toFixed(0)} ms, ` +
                 `visited ${names(ev.visited) || "-"}` +
                 (ev.skipped.length ? `, skipped ${names(ev.skipped.map(s => s.robot))}` : ""));
        if (ev.error)
          note(ev, `${ev.agent} round ${ev.round}: METHOD ${ev.failed_method || ev.method} FAILED: ` +
                   `${ev.error}; ` + (ev.failed_method ? `done again with ${ev.method}`
                                                       : "aborted, no table written"), true);
        break;
      }
      case "method":
        agent(ev.agent).method = ev.method;
        if (ev.previous && ev.previous !== "None")
          note(ev, `${ev.agent} switched method ${ev.previous} → ${ev.method} (round ${ev.round})`);
        break;
      case "skip":
        note(ev, `${ev.agent} skipped ${ev.robot} in round ${ev.round}: ${ev.reason}`, true); break;
      case "share": robot(ev.robot).shares.push(ev.iteration); S.curves++; break;
      case "metrics": {
        const r = robot(ev.robot);
        for (const p of ev.points) { point(r, "q", p[0], p[1]); point(r, "cr", p[0], p[2]); }
        r.iteration = Math.max(r.iteration, ev.points[ev.points.length - 1][0]);
        S.curves++;
        break;
      }
      case "progress": {          // a robot's status (remote robots, before their files)
        const r = robot(ev.robot);
        if (ev.q_sum !== undefined && ev.q_sum !== null) point(r, "q", ev.iteration, ev.q_sum);
        if (ev.cumulative_reward !== undefined && ev.cumulative_reward !== null)
          point(r, "cr", ev.iteration, ev.cumulative_reward);
        r.iteration = Math.max(r.iteration, ev.iteration);
        S.curves++;
        break;
      }
      case "eval": {
        const r = robot(ev.robot);
        point(r, "ev", ev.iteration, ev.progress); S.curves++;
        break;
      }
      case "robot_state": {
        const r = robot(ev.robot), before = r.state;
        r.state = ev.state; S.curves++; S.arenas++;
        if (before !== ev.state && ev.state !== "learning" && ev.state !== "waiting")
          note(ev, `${ev.robot} ${ev.state}${ev.reason ? ": " + ev.reason : ""}` +
                   (ev.inferred ? " (inferred)" : ""), ev.state === "dead" || ev.state === "stalled");
        break;
      }
      case "pose": robot(ev.robot).pose = [ev.x, ev.y, ev.yaw]; S.arenas++; break;
      case "finished": note(ev, `${ev.agent} finished after round ${ev.round}`); break;
      case "aborted": note(ev, `${ev.agent} aborted in round ${ev.round}: ${ev.error}`, true); break;
      case "control":
        note(ev, `${ev.agent} ${ev.status} command ${ev.command}${ev.reason ? " (" + ev.reason + ")" : ""}`); break;
      case "resurrected":
        note(ev, `${ev.agent} resurrected in round ${ev.round} (epoch ${ev.epoch}) from ${ev.from}, ${ev.dead} dead`, true); break;
      case "superseded":
        note(ev, `${ev.agent} copy of epoch ${ev.epoch} superseded by ${ev.by}`, true); break;
      case "error": note(ev, ev.text, true); break;
      case "run_end": S.ended = true; note(ev, "run ended (summary.md written)"); break;
      default:
        note(ev, `${ev.kind} ${JSON.stringify(ev)}`);
    }
  }

  function receive(batch) {
    const t0 = performance.now();
    for (const ev of batch) all[ev.seq] = ev;
    stats.received = all.length;
    if (follow) {
      while (applied < all.length && all[applied]) apply(all[applied++]);
    }
    stats.applyMs += performance.now() - t0;
    schedule();
  }

  let seekTo = null;              // a replay position to go to at the next frame
  function seek(k) {
    S = fresh(); applied = 0; listed = 0; el("events").textContent = "";
    el("network").textContent = ""; el("arenas").textContent = ""; el("agents").textContent = "";
    svgNodes = null; agentLines.clear(); arenaCards.clear(); drawn.clear(); chartsAt = -1e9;
    while (applied < k && applied < all.length) apply(all[applied++]);
    for (const a of S.agents.values()) { a.queue = []; a.shown = { at: a.at, prev: a.prev, phase: a.phase }; }
  }

  // -- drawing --------------------------------------------------------------------------
  function el(id) { return document.getElementById(id); }
  function svg(tag, attrs, parent) {
    const e = document.createElementNS(NS, tag);
    for (const k in attrs) e.setAttribute(k, attrs[k]);
    if (parent) parent.appendChild(e);
    return e;
  }
  // the DOM is touched only where a value changed (an unchanged write still costs a
  // style recalculation and a repaint)
  function setText(node, text) {
    if (node.__text !== text) { node.__text = text; node.textContent = text; }
  }
  function setAttr(node, name, value) {
    const v = String(value), seen = node.__attrs || (node.__attrs = {});
    if (seen[name] !== v) { seen[name] = v; node.setAttribute(name, v); }
  }

  let pending = false, lastFrame = -1e9, chartsAt = -1e9;
  const drawn = new Map();        // what was drawn last: "curves" -> S.curves, ...
  function schedule() {
    if (pending) return;
    pending = true;
    const wait = follow ? Math.max(0, RENDER_MS - (performance.now() - lastFrame)) : 0;
    setTimeout(() => requestAnimationFrame(frame), wait);
  }
  function frame() {
    pending = false; lastFrame = performance.now();
    if (seekTo !== null) { const k = seekTo; seekTo = null; seek(k); }
    render();
  }
  function rel(t) { return S.t0 === null ? "" : `+${Math.max(0, t - S.t0).toFixed(1)} s`; }

  let svgNodes = null;     // robot id -> {g, x, y, info, st}, rebuilt when robots are added
  function positions() {
    const n = S.order.length, cx = 320, cy = 222;
    const rx = n <= 1 ? 0 : Math.min(270, 70 + n * 24), ry = n <= 1 ? 0 : Math.min(165, 60 + n * 18);
    return S.order.map((id, i) => {
      const a = -Math.PI / 2 + (2 * Math.PI * i) / Math.max(1, n);
      return [id, cx + rx * Math.cos(a), cy + ry * Math.sin(a)];
    });
  }
  function buildNetwork() {
    const root = el("network");
    root.textContent = ""; svgNodes = new Map();
    const links = svg("g", { id: "links" }, root);
    const pos = positions(), small = pos.length > 12;
    for (let i = 0; i + 1 < pos.length; i++)
      svg("line", { x1: pos[i][1], y1: pos[i][2], x2: pos[i + 1][1], y2: pos[i + 1][2],
                    stroke: "#ccc", "stroke-width": 1 }, links);
    svg("g", { id: "hops" }, root);
    for (const [id, x, y] of pos) {
      const g = svg("g", { class: "robot", "data-robot": id, transform: `translate(${x},${y})` }, root);
      svg("circle", { r: small ? 11 : 22 }, g);
      const label = svg("text", { "text-anchor": "middle", y: 4, class: "id" }, g);
      label.textContent = id;
      if (!small) {
        const info = svg("text", { "text-anchor": "middle", y: 36, class: "info" }, g);
        const st = svg("text", { "text-anchor": "middle", y: 49, class: "state" }, g);
        svgNodes.set(id, { g, x, y, info, st });
      } else {
        svgNodes.set(id, { g, x, y, info: null, st: svg("title", {}, g) });
      }
    }
    svg("g", { id: "agent-marks" }, root);
    for (const a of S.agents.values()) { a.mark = null; a.cloneMarks = null; }
  }
  // a tree agent's copies: a hollow mark at every robot a copy of the round shown is at
  function drawClones(a, marks, small) {
    if (!a.cloneMarks) a.cloneMarks = new Map();
    for (const [id, m] of a.cloneMarks) if (!a.clones.has(id)) setAttr(m, "visibility", "hidden");
    for (const [id, phase] of a.clones) {
      const n = svgNodes.get(id);
      if (!n) continue;
      let m = a.cloneMarks.get(id);
      if (!m) {
        m = svg("g", { class: "agent-clone", "data-agent": a.name, "data-robot": id }, marks);
        svg("path", { d: "M -6 -5 L 7 0 L -6 5 Z", fill: "none", stroke: a.color, "stroke-width": 2 }, m);
        a.cloneMarks.set(id, m);
      }
      setAttr(m, "visibility", "visible"); setAttr(m, "data-phase", phase);
      setAttr(m, "transform", `translate(${n.x},${n.y + (small ? -20 : -34)})` +
                              (phase === "backward" ? " rotate(180)" : ""));
    }
  }
  function drawNetwork() {
    if (!svgNodes || svgNodes.size !== S.order.length) buildNetwork();
    for (const [id, n] of svgNodes) {
      const r = S.robots.get(id);
      setAttr(n.g, "data-state", r.state);
      if (n.info) {
        setText(n.info, `${r.host}:${r.port} · ${r.arena} · ${r.algo}`);
        setText(n.st, `${r.state} · it ${r.iteration}`);
      } else setText(n.st, `${id} ${r.host}:${r.port} · ${r.arena} · ${r.algo} · ${r.state} · it ${r.iteration}`);
    }
    const hops = el("hops"), marks = el("agent-marks"), small = svgNodes.size > 12;
    let k = 0, more = false;
    for (const a of S.agents.values()) {
      // one queued hop per frame: every move shows at least one frame, however fast
      if (a.queue.length) {
        while (a.queue.length > QUEUE) a.queue.shift();
        a.shown = a.queue.shift();
      }
      more = more || a.queue.length > 0;
      drawClones(a, marks, small);
      const v = a.shown || { at: a.at, prev: a.prev, phase: a.phase };
      if (!a.mark) {
        const g = svg("g", { class: "agent", "data-agent": a.name }, marks);
        svg("path", { d: "M -9 -8 L 11 0 L -9 8 Z", fill: a.color, stroke: a.color, "stroke-width": 2 }, g);
        a.mark = { g, line: svg("line", { stroke: a.color, visibility: "hidden" }, hops) };
      }
      const { g, line } = a.mark, to = svgNodes.get(v.at);
      if (!to) { setAttr(g, "visibility", "hidden"); setAttr(line, "visibility", "hidden"); k++; continue; }
      const x = to.x, y = to.y + (small ? -20 : -34) - 14 * k;
      setAttr(g, "visibility", "visible");
      setAttr(g, "transform", `translate(${x},${y})` + (v.phase === "backward" ? " rotate(180)" : ""));
      setAttr(g, "data-robot", v.at); setAttr(g, "data-phase", v.phase);
      setAttr(g, "data-x", x.toFixed(1)); setAttr(g, "data-y", y.toFixed(1));
      setAttr(g, "data-moves", a.moves);
      const from = svgNodes.get(v.prev);
      if (from && from !== to && v.phase !== "rest") {
        setAttr(line, "class", `hop-line ${v.phase}`);
        setAttr(line, "x1", from.x); setAttr(line, "y1", from.y);
        setAttr(line, "x2", to.x); setAttr(line, "y2", to.y);
        setAttr(line, "visibility", "visible");
      } else setAttr(line, "visibility", "hidden");
      k++;
    }
    return more;
  }
  const agentLines = new Map();   // agent name -> its header line's parts
  function drawAgents() {
    const box = el("agents");
    for (const a of S.agents.values()) {
      let line = agentLines.get(a.name);
      if (!line) {
        const div = document.createElement("div"); div.className = "agent-line";
        div.setAttribute("data-agent", a.name);
        div.innerHTML = `<span class="swatch"></span><b class="name"></b>` +
          `<span>round <span class="round">0</span>/<span class="of"></span></span>` +
          `<span class="method"></span><span class="last"></span><span class="where"></span>`;
        div.querySelector(".swatch").style.background = a.color;
        div.querySelector(".name").textContent = a.name;
        box.appendChild(div);
        line = {};
        for (const part of ["round", "of", "method", "last", "where"]) line[part] = div.querySelector("." + part);
        line.round.id = `round-${a.name}`;
        agentLines.set(a.name, line);
      }
      setText(line.round, String(a.round)); setAttr(line.round, "data-round", a.round);
      setText(line.of, String(a.rounds || "?"));
      setText(line.method, a.method);
      setText(line.last, a.lastMs === null ? "" : `last round ${a.lastMs.toFixed(0)} ms`);
      const v = a.shown || a;          // where the mark is drawn (hops shown one a frame)
      setText(line.where, v.at ? `at ${v.at} (${v.phase})` : "");
    }
  }
  function drawChart(id, key) {
    const c = el(id), ctx = c.getContext("2d"), W = c.width, H = c.height;
    const L = 48, R = 8, T = 8, B = 22;
    ctx.clearRect(0, 0, W, H);
    let xmax = (S.run && S.run.iterations) || 1, ymin = 0, ymax = 1e-9, n = 0;
    for (const r of S.robots.values()) {
      if (!r[key].length) continue;
      ymin = Math.min(ymin, r.ext[key][0]); ymax = Math.max(ymax, r.ext[key][1]); n += r[key].length;
    }
    const X = v => L + (W - L - R) * v / xmax, Y = v => T + (H - T - B) * (1 - (v - ymin) / (ymax - ymin));
    ctx.strokeStyle = "#999"; ctx.lineWidth = 1; ctx.beginPath();
    ctx.moveTo(L, T); ctx.lineTo(L, H - B); ctx.lineTo(W - R, H - B); ctx.stroke();
    ctx.fillStyle = "#555"; ctx.font = "10px sans-serif";
    ctx.fillText(ymax.toPrecision(3), 2, T + 8); ctx.fillText(ymin.toPrecision(3), 2, H - B);
    ctx.fillText("0", L, H - 8); ctx.fillText(`${xmax} iterations`, W - R - 80, H - 8);
    for (const r of S.robots.values()) {
      ctx.strokeStyle = r.color; ctx.globalAlpha = 0.5;
      ctx.beginPath();
      for (const it of r.shares) { ctx.moveTo(X(it), H - B); ctx.lineTo(X(it), H - B + 5); }
      ctx.stroke(); ctx.globalAlpha = 1;
      const pts = r[key]; if (!pts.length) continue;
      // at most about MAX_PTS points per curve (the last one always)
      const step = Math.max(1, Math.ceil(pts.length / MAX_PTS));
      ctx.lineWidth = r.state === "dead" ? 1 : 1.5; ctx.setLineDash(r.state === "dead" ? [3, 3] : []);
      ctx.beginPath(); ctx.moveTo(X(pts[0][0]), Y(pts[0][1]));
      for (let i = step; i < pts.length; i += step) ctx.lineTo(X(pts[i][0]), Y(pts[i][1]));
      const last = pts[pts.length - 1];
      ctx.lineTo(X(last[0]), Y(last[1]));
      if (pts.length === 1) ctx.arc(X(last[0]), Y(last[1]), 1.5, 0, 2 * Math.PI);
      ctx.stroke(); ctx.setLineDash([]);
    }
    c.setAttribute("data-points", n);
    return n;
  }
  function drawLegend() {
    const box = el("legend");
    if (box.childElementCount === S.order.length + 1) return;
    box.textContent = "";
    const states = document.createElement("div"); states.className = "states";
    for (const st of ["learning", "waiting", "stalled", "skipped", "dead", "done"])
      states.insertAdjacentHTML("beforeend", `<span class="st" data-state="${st}">● ${st}</span> `);
    box.appendChild(states);
    for (const id of S.order) {
      const s = document.createElement("span");
      s.style.color = S.robots.get(id).color; s.textContent = `■ ${id} `; box.appendChild(s);
    }
  }
  const arenaCards = new Map();   // robot id -> {card, pose, cap}
  function drawArenas() {
    const box = el("arenas");
    for (const id of S.order) {
      const r = S.robots.get(id);
      let a = arenaCards.get(id);
      if (!a && r.spec) {
        const card = document.createElement("div"); card.className = "arena"; card.setAttribute("data-robot", id);
        const [w, d] = r.spec.size, s = svg("svg", { viewBox: `${-w / 2} ${-d / 2} ${w} ${d}` });
        const g = svg("g", { transform: "scale(1,-1)" }, s);
        svg("rect", { x: -w / 2, y: -d / 2, width: w, height: d, fill: "none", stroke: "#333", "stroke-width": w / 50 }, g);
        for (const b of r.spec.blocks)
          svg("rect", { x: -b.size[0] / 2, y: -b.size[1] / 2, width: b.size[0], height: b.size[1], fill: "#777",
                        transform: `translate(${b.center[0]},${b.center[1]}) rotate(${b.yaw * 180 / Math.PI})` }, g);
        const pose = svg("g", { class: "pose", visibility: "hidden" }, g);
        svg("circle", { r: w / 25, fill: r.color }, pose);
        svg("line", { x1: 0, y1: 0, x2: w / 12, y2: 0, stroke: "#000", "stroke-width": w / 120 }, pose);
        card.appendChild(s);
        const cap = document.createElement("div"); card.appendChild(cap);
        box.appendChild(card);
        a = { card, pose, cap };
        arenaCards.set(id, a);
      }
      if (!a) continue;
      setAttr(a.card, "data-state", r.state);
      setText(a.cap, `${id} · ${r.spec.name} · ${r.state}`);
      const p = r.pose || (r.spec.start && r.iteration === 0 ? r.spec.start : null);
      if (p) {
        setAttr(a.pose, "visibility", "visible");
        setAttr(a.pose, "transform", `translate(${p[0].toFixed(3)},${p[1].toFixed(3)}) rotate(${(p[2] * 180 / Math.PI).toFixed(0)})`);
        setAttr(a.card, "data-pose", `${p[0].toFixed(3)},${p[1].toFixed(3)}`);
      } else setAttr(a.pose, "visibility", "hidden");
    }
  }
  function drawList() {
    const ol = el("events");
    const fresh = S.list.slice(Math.max(listed, S.list.length - MAX_LIST));
    if (!fresh.length) return;
    const part = document.createDocumentFragment();
    for (let i = fresh.length - 1; i >= 0; i--) {
      const item = fresh[i], li = document.createElement("li");
      li.setAttribute("data-kind", item.kind); if (item.fault) li.setAttribute("data-fault", "1");
      const t = document.createElement("span"); t.className = "t"; t.textContent = rel(item.t);
      li.appendChild(t); li.appendChild(document.createTextNode(item.text));
      part.appendChild(li);
    }
    ol.insertBefore(part, ol.firstChild);
    listed = S.list.length;
    while (ol.childElementCount > MAX_LIST) ol.removeChild(ol.lastChild);
  }
  function drawHeader() {
    if (S.run) {
      setText(el("run-name"), String(S.run.name));
      setText(el("run-info"), `${S.order.length} robots · ${S.run.iterations} iterations · ` +
        `respite ${S.run.respite} · ${S.run.mode} · seed ${S.run.seed}`);
    }
    const st = el("run-status");
    const status = !stats.connected && !S.ended ? "disconnected" : S.ended ? "finished" : "live";
    setText(st, status); setAttr(st, "data-status", status);
    setAttr(slider, "max", all.length);
    if (follow) { if (slider.value !== String(applied)) slider.value = String(applied); }
    const last = applied ? all[applied - 1] : null;
    // live: the count in steps of a hundred (a label that changes each frame is a repaint)
    setText(el("replay-label"), follow ? `live (${applied < 100 ? applied : Math.floor(applied / 100) * 100}+ events)` :
      `event ${applied}/${all.length} ${last ? rel(last.t) : ""}`);
  }
  function render() {
    const t0 = performance.now();
    drawHeader(); const more = drawNetwork(); drawAgents(); drawLegend(); drawList();
    let later = more;
    const chartsDue = !follow || S.ended || t0 - chartsAt >= CHART_MS;
    const changed = drawn.get("curves") !== S.curves || drawn.get("arenas") !== S.arenas;
    if (changed && chartsDue) {
      chartsAt = t0;
      if (drawn.get("curves") !== S.curves) {
        drawn.set("curves", S.curves);
        for (const [id, key] of CURVES) {
          const n = drawChart(id, key);
          if (key === "ev") el("curves-panel").setAttribute("data-eval", n ? "1" : "0");
        }
      }
      if (drawn.get("arenas") !== S.arenas) { drawn.set("arenas", S.arenas); drawArenas(); }
    } else if (changed) later = true;
    stats.renders++; stats.renderMs += performance.now() - t0;
    if (stats.firstPaintMs === null && S.order.length && S.run && S.robots.size >= S.run.robots)
      stats.firstPaintMs = performance.now();
    if (later) schedule();
  }

  // -- wiring ---------------------------------------------------------------------------
  const slider = el("replay");
  slider.addEventListener("input", () => {
    // a drag fires many inputs: the page goes to the last one, once a frame
    const k = Number(slider.value);
    follow = k >= all.length;
    seekTo = k; schedule();
  });
  el("live").addEventListener("click", () => { follow = true; seekTo = all.length; schedule(); });
  const source = new EventSource("/events");
  source.onopen = () => { stats.connected = true; schedule(); };
  source.onerror = () => { stats.connected = false; schedule(); };
  source.onmessage = (m) => receive(JSON.parse(m.data));
  schedule();
})();
