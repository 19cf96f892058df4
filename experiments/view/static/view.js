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
  const MAX_LIST = 300;
  const RENDER_MS = 250;           // redraw of the network, counters and list at most this often
  const CHART_MS = 1000;          // curves and arenas at most this often (live)
  const HOP_MS = 180;             // a hop stays on screen at least this long (live)
  const QUEUE = 8;                // hops waiting to be shown at most (older ones dropped)

  const all = [];                 // every event received, by seq
  let S = fresh();                // the model at the replay position
  let applied = 0;                // events applied to S
  let follow = true;              // apply new events as they come
  let dirty = true, timer = null, listed = [], chartsAt = -1e9;
  const stats = { received: 0, applyMs: 0, renderMs: 0, renders: 0, firstPaintMs: null,
                  connected: false };
  window.dfrlView = { stats, model: () => S };

  function fresh() {
    return { run: null, robots: new Map(), order: [], agents: new Map(), t0: null,
             ended: false, list: [], listSeq: 0 };
  }
  function robot(id) {
    let r = S.robots.get(id);
    if (!r) {
      r = { id, host: "", port: "", arena: "", algo: "", state: "learning", q: [], cr: [],
            shares: [], pose: null, spec: null, iteration: 0, color: COLORS[S.order.length % COLORS.length] };
      S.robots.set(id, r); S.order.push(id);
    }
    return r;
  }
  function agent(name) {
    let a = S.agents.get(name);
    if (!a) {
      a = { name, algo: "", method: "", rounds: 0, round: 0, lastMs: null, at: null,
            phase: "rest", prev: null, moves: 0, itinerary: [], queue: [], shown: null,
            shownAt: 0,
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
  }

  // -- the model ------------------------------------------------------------------------
  function apply(ev) {
    switch (ev.kind) {
      case "run":
        S.run = ev; S.t0 = ev.t; break;
      case "robot": {
        const r = robot(ev.robot);
        Object.assign(r, { host: ev.host, port: ev.port, arena: ev.arena, algo: ev.algo,
                           node: ev.node, joined: ev.joined });
        note(ev, `${ev.joined ? "joined" : "node up"}: ${ev.robot} ${ev.host}:${ev.port} ` +
                 `arena ${ev.arena}, ${ev.algo}`);
        break;
      }
      case "arena": robot(ev.robot).spec = ev; break;
      case "agent": {
        const a = agent(ev.agent);
        Object.assign(a, { algo: ev.algo, method: ev.method, rounds: ev.rounds,
                           itinerary: ev.itinerary || [] });
        if (!a.at && a.itinerary.length) a.at = a.itinerary[0];
        note(ev, `agent ${ev.agent} (${ev.method}, ${ev.rounds} rounds): ` +
                 ((ev.itinerary || []).length <= 8 ? ev.itinerary.join(" → ") : names(ev.itinerary)));
        break;
      }
      case "hop": {
        const a = agent(ev.agent);
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
        break;
      }
      case "method":
        agent(ev.agent).method = ev.method;
        if (ev.previous && ev.previous !== "None")
          note(ev, `${ev.agent} switched method ${ev.previous} → ${ev.method} (round ${ev.round})`);
        break;
      case "skip":
        note(ev, `${ev.agent} skipped ${ev.robot} in round ${ev.round}: ${ev.reason}`, true); break;
      case "share": robot(ev.robot).shares.push(ev.iteration); break;
      case "metrics": {
        const r = robot(ev.robot);
        for (const p of ev.points) { r.q.push([p[0], p[1]]); r.cr.push([p[0], p[2]]); }
        r.iteration = ev.points[ev.points.length - 1][0];
        break;
      }
      case "robot_state": {
        const r = robot(ev.robot), before = r.state;
        r.state = ev.state;
        if (before !== ev.state && ev.state !== "learning" && ev.state !== "waiting")
          note(ev, `${ev.robot} ${ev.state}${ev.reason ? ": " + ev.reason : ""}` +
                   (ev.inferred ? " (inferred)" : ""), ev.state === "dead" || ev.state === "stalled");
        break;
      }
      case "pose": robot(ev.robot).pose = [ev.x, ev.y, ev.yaw]; break;
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
    slider.max = String(all.length);
    if (follow) slider.value = String(applied);
    schedule();
  }

  function seek(k) {
    S = fresh(); applied = 0; listed = []; el("events").textContent = "";
    el("network").textContent = ""; el("arenas").textContent = ""; svgNodes = null;
    while (applied < k && applied < all.length) apply(all[applied++]);
    for (const a of S.agents.values()) { a.queue = []; a.shown = { at: a.at, prev: a.prev, phase: a.phase }; }
    schedule();
  }

  // -- drawing --------------------------------------------------------------------------
  function el(id) { return document.getElementById(id); }
  function svg(tag, attrs, parent) {
    const e = document.createElementNS(NS, tag);
    for (const k in attrs) e.setAttribute(k, attrs[k]);
    if (parent) parent.appendChild(e);
    return e;
  }
  function schedule() {
    dirty = true;
    if (timer === null) timer = setTimeout(() => { timer = null; if (dirty) render(); }, RENDER_MS);
  }
  function later(ms) {
    if (timer === null) timer = setTimeout(() => { timer = null; render(); }, ms);
  }
  function rel(t) { return S.t0 === null ? "" : `+${Math.max(0, t - S.t0).toFixed(1)} s`; }

  let svgNodes = null;     // robot id -> {g, x, y}, rebuilt when robots are added
  function positions() {
    const n = S.order.length, cx = 320, cy = 222;
    const rx = n <= 1 ? 0 : Math.min(270, 70 + n * 24), ry = n <= 1 ? 0 : Math.min(165, 60 + n * 18);
    return S.order.map((id, i) => {
      const a = -Math.PI / 2 + (2 * Math.PI * i) / Math.max(1, n);
      return [id, cx + rx * Math.cos(a), cy + ry * Math.sin(a)];
    });
  }
  function drawNetwork() {
    const root = el("network");
    if (!svgNodes || svgNodes.size !== S.order.length) {
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
        const label = svg("text", { "text-anchor": "middle", y: small ? 4 : 4, class: "id" }, g);
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
    }
    for (const [id, n] of svgNodes) {
      const r = S.robots.get(id);
      n.g.setAttribute("data-state", r.state);
      if (n.info) {
        n.info.textContent = `${r.host}:${r.port} · ${r.arena} · ${r.algo}`;
        n.st.textContent = `${r.state} · it ${r.iteration}`;
      } else n.st.textContent = `${id} ${r.host}:${r.port} · ${r.arena} · ${r.algo} · ${r.state} · it ${r.iteration}`;
    }
    const hops = el("hops"), marks = el("agent-marks");
    hops.textContent = "";
    let k = 0;
    const now = performance.now();
    for (const a of S.agents.values()) {
      if (a.queue.length && (now - a.shownAt >= HOP_MS || !a.shown)) {
        while (a.queue.length > QUEUE) a.queue.shift();
        a.shown = a.queue.shift(); a.shownAt = now; a.shows = (a.shows || 0) + 1;
      }
      if (a.queue.length) later(HOP_MS);
      const v = a.shown || { at: a.at, prev: a.prev, phase: a.phase };
      const to = svgNodes.get(v.at);
      let g = marks.querySelector(`[data-agent="${CSS.escape(a.name)}"]`);
      if (!g) {
        g = svg("g", { class: "agent", "data-agent": a.name }, marks);
        svg("path", { d: "M -9 -8 L 11 0 L -9 8 Z", fill: a.color, stroke: a.color, "stroke-width": 2 }, g);
      }
      if (!to) { g.setAttribute("visibility", "hidden"); k++; continue; }
      const small = svgNodes.size > 12, dx = 0, dy = (small ? -20 : -34) - 14 * k;
      const x = to.x + dx, y = to.y + dy;
      g.setAttribute("visibility", "visible");
      g.setAttribute("transform", `translate(${x},${y})` + (v.phase === "backward" ? " rotate(180)" : ""));
      g.setAttribute("data-robot", v.at); g.setAttribute("data-phase", v.phase);
      g.setAttribute("data-x", x.toFixed(1)); g.setAttribute("data-y", y.toFixed(1));
      g.setAttribute("data-moves", a.moves);
      const from = svgNodes.get(v.prev);
      if (from && from !== to && v.phase !== "rest")
        svg("line", { class: `hop-line ${v.phase}`, x1: from.x, y1: from.y, x2: to.x, y2: to.y,
                      stroke: a.color }, hops);
      k++;
    }
  }
  function drawAgents() {
    const box = el("agents");
    for (const a of S.agents.values()) {
      let line = box.querySelector(`[data-agent="${CSS.escape(a.name)}"]`);
      if (!line) {
        line = document.createElement("div"); line.className = "agent-line";
        line.setAttribute("data-agent", a.name);
        line.innerHTML = `<span class="swatch"></span><b class="name"></b>` +
          `<span>round <span class="round">0</span>/<span class="of"></span></span>` +
          `<span class="method"></span><span class="last"></span><span class="where"></span>`;
        line.querySelector(".swatch").style.background = a.color;
        line.querySelector(".name").textContent = a.name;
        box.appendChild(line);
      }
      const rnd = line.querySelector(".round");
      rnd.textContent = a.round; rnd.id = `round-${a.name}`; rnd.setAttribute("data-round", a.round);
      line.querySelector(".of").textContent = a.rounds || "?";
      line.querySelector(".method").textContent = a.method;
      line.querySelector(".last").textContent = a.lastMs === null ? "" : `last round ${a.lastMs.toFixed(0)} ms`;
      line.querySelector(".where").textContent = a.at ? `at ${a.at} (${a.phase})` : "";
    }
  }
  function drawChart(id, key) {
    const c = el(id), ctx = c.getContext("2d"), W = c.width, H = c.height;
    const L = 48, R = 8, T = 8, B = 22;
    ctx.clearRect(0, 0, W, H);
    let xmax = (S.run && S.run.iterations) || 1, ymin = 0, ymax = 1e-9, n = 0;
    for (const r of S.robots.values())
      for (const p of r[key]) { if (p[1] > ymax) ymax = p[1]; if (p[1] < ymin) ymin = p[1]; n++; }
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
      ctx.lineWidth = r.state === "dead" ? 1 : 1.5; ctx.setLineDash(r.state === "dead" ? [3, 3] : []);
      ctx.beginPath(); ctx.moveTo(X(pts[0][0]), Y(pts[0][1]));
      for (let i = 1; i < pts.length; i++) ctx.lineTo(X(pts[i][0]), Y(pts[i][1]));
      ctx.stroke(); ctx.setLineDash([]);
    }
    c.setAttribute("data-points", n);
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
  function drawArenas() {
    const box = el("arenas");
    for (const id of S.order) {
      const r = S.robots.get(id);
      let card = box.querySelector(`[data-robot="${CSS.escape(id)}"]`);
      if (!card && r.spec) {
        card = document.createElement("div"); card.className = "arena"; card.setAttribute("data-robot", id);
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
      }
      if (!card) continue;
      card.setAttribute("data-state", r.state);
      card.lastChild.textContent = `${id} · ${r.spec.name} · ${r.state}`;
      const p = r.pose || (r.spec.start && r.iteration === 0 ? r.spec.start : null);
      const pose = card.querySelector(".pose");
      if (p) {
        pose.setAttribute("visibility", "visible");
        pose.setAttribute("transform", `translate(${p[0]},${p[1]}) rotate(${p[2] * 180 / Math.PI})`);
      } else pose.setAttribute("visibility", "hidden");
    }
  }
  function drawList() {
    const ol = el("events");
    const fresh = S.list.slice(listed.length);
    for (const item of fresh) {
      const li = document.createElement("li");
      li.setAttribute("data-kind", item.kind); if (item.fault) li.setAttribute("data-fault", "1");
      const t = document.createElement("span"); t.className = "t"; t.textContent = rel(item.t);
      li.appendChild(t); li.appendChild(document.createTextNode(item.text));
      ol.insertBefore(li, ol.firstChild);
    }
    listed = S.list.slice();
    while (ol.childElementCount > MAX_LIST) ol.removeChild(ol.lastChild);
  }
  function drawHeader() {
    if (S.run) {
      el("run-name").textContent = S.run.name;
      el("run-info").textContent = `${S.order.length} robots · ${S.run.iterations} iterations · ` +
        `respite ${S.run.respite} · ${S.run.mode} · seed ${S.run.seed}`;
    }
    const st = el("run-status");
    const status = !stats.connected && !S.ended ? "disconnected" : S.ended ? "finished" : "live";
    st.textContent = status; st.setAttribute("data-status", status);
    const last = applied ? all[applied - 1] : null;
    el("replay-label").textContent = follow ? `live (${applied} events)` :
      `event ${applied}/${all.length} ${last ? rel(last.t) : ""}`;
  }
  function render() {
    const t0 = performance.now();
    dirty = false;
    drawHeader(); drawAgents(); drawNetwork(); drawLegend(); drawList();
    if (!follow || S.ended || t0 - chartsAt >= CHART_MS) {
      chartsAt = t0; drawChart("chart-q", "q"); drawChart("chart-cr", "cr"); drawArenas();
    } else later(CHART_MS - (t0 - chartsAt));
    stats.renders++; stats.renderMs += performance.now() - t0;
    if (stats.firstPaintMs === null && S.order.length && S.run && S.robots.size >= S.run.robots)
      stats.firstPaintMs = performance.now();
  }

  // -- wiring ---------------------------------------------------------------------------
  const slider = el("replay");
  slider.addEventListener("input", () => {
    const k = Number(slider.value);
    follow = k >= all.length;
    seek(k);
  });
  el("live").addEventListener("click", () => { follow = true; seek(all.length); slider.value = slider.max; });
  const source = new EventSource("/events");
  source.onopen = () => { stats.connected = true; schedule(); };
  source.onerror = () => { stats.connected = false; schedule(); };
  source.onmessage = (m) => receive(JSON.parse(m.data));
  render();
})();
