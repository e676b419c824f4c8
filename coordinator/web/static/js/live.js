// Follow and steer a live run (paper section 5): frames from the server are applied once per screen
// repaint (requestAnimationFrame), the latest marking winning; fired transitions flash; running actions
// and latched events sit beside their places; control places take token insertions and removals.

import { el, fmt, seconds } from "./ui.js";

const END_STATES = new Set(["completed", "stuck", "waiting_for_operator", "aborted", "deadline", "interrupted"]);

// what the page measured, for bench/console.py: latency from firing (server clock) to the repaint showing it
const stats = { frames: 0, paints: 0, latencies: new Float64Array(1 << 16), n: 0 };
window.petrobotStats = {
  get frames() { return stats.frames; }, get paints() { return stats.paints; },
  latencies() { const k = Math.min(stats.n, stats.latencies.length); return Array.from(stats.latencies.subarray(0, k)); },
  reset() { stats.frames = 0; stats.paints = 0; stats.n = 0; },
};

export function initLive(app) {
  const live = {
    runId: null, marking: {}, firings: 0, paused: false, state: { state: "", reason: "", detail: [] },
    running: new Map(), latched: {}, learner: {}, results: [], operator: [], errors: [], pulses: {},
    offset: 0, ended: false, health: null,
  };
  app.live = live;
  let queue = [];
  let scheduled = false;
  let lastPanel = 0;

  // the server's node → {connected, heartbeat_rtt_s, in_flight}, as the health table reads it
  function toHealth(nodes) {
    if (!nodes) return null;
    const list = Object.entries(nodes).map(([node, h]) => ({ node, connected: h.connected, rtt_s: h.heartbeat_rtt_s, in_flight: h.in_flight }));
    return list.length ? { nodes: list } : { note: "this run's client does not report node health" };
  }

  function nowServer() { return Date.now() / 1000 + live.offset; }

  /** Take a whole snapshot (welcome, run start, resync). */
  function load(snapshot) {
    live.runId = snapshot.run;
    live.marking = { ...snapshot.marking };
    live.firings = snapshot.firings;
    live.paused = snapshot.paused;
    live.state = snapshot.state || live.state;
    live.running = new Map((snapshot.running || []).map((r) => [r.i, r]));
    live.latched = snapshot.latched || {};
    live.learner = snapshot.learner || {};
    live.operator = snapshot.operator || [];
    live.errors = snapshot.errors || [];
    live.results = snapshot.results || [];
    live.health = toHealth(snapshot.nodes);
    live.offset = (snapshot.server_time || Date.now() / 1000) - Date.now() / 1000;
    live.ended = END_STATES.has(live.state.state);
    if (app.mode === "live") paint(true);
  }

  function onFrame(frame) {
    stats.frames++;
    queue.push(frame);
    if (!scheduled) { scheduled = true; requestAnimationFrame(apply); }
  }

  // one repaint for every frame that arrived since the last one
  function apply() {
    scheduled = false;
    const frames = queue;
    queue = [];
    if (!frames.length) return;
    const changed = {};
    const fired = new Set();
    let oldest = null;
    for (const f of frames) {
      live.offset = f.t - Date.now() / 1000;
      if (f.marking) Object.assign(changed, f.marking);
      if (f.fired) { for (const t of Object.keys(f.fired)) fired.add(t); if (oldest === null) oldest = f.t_fired[0]; }
      for (const s of f.started || []) live.running.set(s.i, s);
      for (const [i, text] of Object.entries(f.feedback || {})) { const r = live.running.get(i); if (r) r.feedback = text; }
      for (const r of f.ended || []) {
        live.running.delete(r.i);
        live.results.push(r);
        if (r.status === "error") live.errors.push(r);
      }
      if (f.latched) live.latched = f.latched;
      if (f.learner) Object.assign(live.learner, f.learner);
      for (const o of f.operator || []) live.operator.push(o);
      if (f.pulses) for (const [e, n] of Object.entries(f.pulses)) live.pulses[e] = (live.pulses[e] || 0) + n;
      if (f.state) live.state = f.state;
      if (f.nodes) live.health = toHealth(f.nodes);
      live.firings = f.firings;
      live.paused = f.paused;
    }
    if (live.results.length > 40) live.results.splice(0, live.results.length - 40);
    if (live.errors.length > 20) live.errors.splice(0, live.errors.length - 20);
    if (live.operator.length > 20) live.operator.splice(0, live.operator.length - 20);
    for (const [p, n] of Object.entries(changed)) { if (n) live.marking[p] = n; else delete live.marking[p]; }
    live.ended = END_STATES.has(live.state.state);
    if (app.mode === "live") {
      app.graph.setMarking(changed);
      if (fired.size) app.graph.flash(fired);
      // badges and panels only when actions started, ended or latched: a run firing thousands of
      // transitions a second repaints tokens and flashes, not the whole drawing's decorations
      const detail = frames.some((f) => f.started || f.ended || f.latched || f.feedback);
      if (detail) paintDetails(true); else header();
      const fresh = frames.find((f) => f.learner || f.operator || f.state || f.nodes);
      if (fresh) renderPanelsSoon(true);
      if (oldest !== null) {
        // measured after this repaint's work: the drawing below shows these firings
        const lat = (performance.timeOrigin + performance.now()) / 1000 - oldest;
        stats.latencies[stats.n % stats.latencies.length] = lat;
        stats.n++;
      }
      stats.paints++;
    }
    for (const f of frames) for (const o of f.operator || []) {
      const what = o.command === "invalid" ? `"${o.text}"` : [o.command, o.place, o.place ? o.count : null].filter((x) => x !== null).join(" ");
      if (!o.ok) app.message(`operator ${what} refused: ${o.reason}`, "bad");
    }
  }

  function badges() {
    const map = new Map();
    const now = nowServer();
    for (const r of live.running.values()) {
      const prev = map.get(r.place);
      const line = `\u25B6 ${r.action} @ ${r.node || "not placed"}  ${seconds(Math.max(0, now - r.t))}` +
        (r.feedback ? `\n  ${r.feedback.length > 48 ? r.feedback.slice(0, 47) + "\u2026" : r.feedback}` : "");
      map.set(r.place, { text: prev ? `${prev.text}\n${line}` : line, latched: false });
    }
    for (const [place, items] of Object.entries(live.latched)) {
      if (map.has(place)) continue;
      const text = items.map(([, action, events]) => `\u2713 ${events.filter((e) => !/\.(ok|success)$/.test(e) || events.length <= 2).join(" ")} (${action})`).join("\n");
      map.set(place, { text, latched: true });
    }
    return map;
  }

  function paintDetails(force) {
    app.graph.setBadges(badges());
    header();
    if (force) renderPanelsSoon(false);
  }

  function paint(full) {
    if (full) app.graph.setMarking({ ...live.marking }, true);
    paintDetails(true);
    renderPanelsSoon(true);
  }

  let panelTimer = null;
  function renderPanelsSoon(now) {
    if (now) { clearTimeout(panelTimer); panelTimer = null; renderPanels(); return; }
    if (panelTimer) return;
    panelTimer = setTimeout(() => { panelTimer = null; renderPanels(); }, 200);
  }

  // running actions' elapsed times advance between frames
  setInterval(() => {
    if (app.mode !== "live" || !live.running.size) return;
    app.graph.setBadges(badges());
    if (Date.now() - lastPanel > 450) renderPanels();
  }, 250);

  let lastButtons = "";
  function header() {
    const s = live.state.state || "";
    const state = document.getElementById("run-state");
    const shown = s === "started" || s === "resumed" ? "running" : s;
    state.textContent = shown || " ";
    state.className = "run-state " + (END_STATES.has(s) ? (s === "completed" ? "ended" : "error") : shown);
    document.getElementById("firings").textContent = `${live.firings} firings`;
    const waiting = document.getElementById("waiting");
    waiting.textContent = live.state.reason ? live.state.reason : "";
    waiting.title = (live.state.detail || []).join("\n");
    const control = app.control && !live.ended;
    const key = `${control}|${live.paused}|${live.ended}`;
    if (key === lastButtons) return;
    lastButtons = key;
    const note = !app.control ? "read-only: open the URL with its token to steer the run" : live.ended ? "the run has ended" : "";
    for (const b of document.querySelectorAll("#live-bar button")) {
      const cmd = b.dataset.cmd;
      let off = !control;
      if (cmd === "pause") off = off || live.paused;
      if (cmd === "resume") off = off || !live.paused;
      b.disabled = off;
      b.title = note || b.getAttribute("data-title") || b.title;
    }
  }

  // ------------------------------------------------------------------ panels
  function renderPanels() {
    lastPanel = Date.now();
    renderRun();
    renderLearning();
  }

  function renderRun() {
    const panel = document.getElementById("panel-run");
    if (app.mode !== "live" && app.mode !== "replay") return;
    if (app.mode === "replay") return;  // the replay draws this panel itself
    panel.replaceChildren();
    const s = live.state;
    panel.append(el("h3", {}, `Run ${live.runId || ""}`));
    panel.append(el("p", {}, el("b", {}, s.state || "starting"), s.reason ? ` \u2014 ${s.reason}` : ""));
    if ((s.detail || []).length) panel.append(el("ul", { class: "small" }, ...s.detail.map((d) => el("li", {}, d))));
    panel.append(el("h4", {}, "running primitive actions"));
    if (!live.running.size) panel.append(el("p", { class: "empty" }, "none"));
    else {
      const t = el("table", { class: "grid" }, el("tr", {}, ...["task", "action", "node", "elapsed", "feedback"].map((h) => el("th", {}, h))));
      const now = nowServer();
      for (const r of live.running.values()) {
        t.append(el("tr", {}, el("td", {}, r.task), el("td", { class: "mono" }, r.action),
          el("td", {}, r.node || el("span", { class: "unplaced" }, "not placed")), el("td", { class: "num" }, seconds(now - r.t)),
          el("td", { class: "small mono feedback" }, r.feedback || "")));
      }
      panel.append(t);
    }
    const latched = Object.entries(live.latched);
    panel.append(el("h4", {}, "latched events (waiting for a transition)"));
    if (!latched.length) panel.append(el("p", { class: "empty" }, "none"));
    else panel.append(el("ul", { class: "mono" }, ...latched.flatMap(([place, items]) =>
      items.map(([inst, action, events]) => el("li", {}, `${place}: ${events.join(", ")}  (${action}, ${inst})`)))));
    panel.append(el("h4", {}, "nodes"));
    panel.append(healthTable());
    panel.append(el("h4", {}, "last results"));
    if (!live.results.length) panel.append(el("p", { class: "empty" }, "none yet"));
    else {
      const t = el("table", { class: "grid" }, el("tr", {}, ...["task/action", "status", "time", "reason"].map((h) => el("th", {}, h))));
      for (const r of live.results.slice(-12).reverse()) {
        const cls = r.status === "error" ? "node-bad" : r.status === "success" ? "node-ok" : "";
        t.append(el("tr", {}, el("td", { class: "mono" }, `${r.task}/${r.action}`),
          el("td", { class: cls }, r.status + (r.outcome ? ` (${r.outcome})` : "")), el("td", { class: "num" }, seconds(r.wall_s)),
          el("td", { class: "small" }, r.reason || "")));
      }
      panel.append(t);
    }
    if (live.operator.length) {
      panel.append(el("h4", {}, "operator commands"));
      panel.append(el("ul", { class: "small" }, ...live.operator.slice(-8).reverse().map((o) => el("li", { class: o.ok ? "" : "node-bad" },
        `${o.command}${o.place ? " " + o.place + " " + o.count : ""}${o.text ? ` "${o.text}"` : ""}: ${o.ok ? "applied" : "refused: " + o.reason}`))));
    }
    const pulses = Object.entries(live.pulses);
    if (pulses.length) panel.append(el("p", { class: "small" }, "external events: " + pulses.map(([e, n]) => `${e} \u00d7${n}`).join(", ")));
  }

  function healthTable() {
    const h = live.health;
    if (!h || !h.nodes) return el("p", { class: "empty" }, h && h.note ? h.note : "no node health yet");
    const t = el("table", { class: "grid" }, el("tr", {}, ...["node", "link", "round trip", "in flight"].map((x) => el("th", {}, x))));
    for (const n of h.nodes) {
      t.append(el("tr", {}, el("td", {}, n.node), el("td", { class: n.connected ? "node-ok" : "node-bad" }, n.connected ? "connected" : "down"),
        el("td", { class: "num" }, n.rtt_s === null || n.rtt_s === undefined ? "-" : `${(n.rtt_s * 1000).toFixed(1)} ms`),
        el("td", { class: "num" }, String(n.in_flight ?? "-"))));
    }
    return t;
  }

  function renderLearning() {
    const panel = document.getElementById("panel-learning");
    if (app.mode !== "live") return;
    panel.replaceChildren();
    renderLearner(panel, live.learner);
  }

  // ------------------------------------------------------------------ steering
  const pop = document.getElementById("steer-pop");
  let popPlace = null;
  app.graph.cy.on("tap", "node.place", (ev) => {
    if (app.mode !== "live") return;
    const place = app.currentDraft()?.places.find((p) => p.id === ev.target.id());
    if (!place || place.kind !== "control") { hidePop(); return; }
    popPlace = place.id;
    const rp = ev.target.renderedPosition();
    pop.style.left = `${rp.x + 30}px`;
    pop.style.top = `${Math.max(4, rp.y - 30)}px`;
    document.getElementById("steer-title").textContent = `${place.label || place.id}`;
    updatePop();
    pop.hidden = false;
  });
  app.graph.cy.on("tap", (ev) => { if (ev.target === app.graph.cy) hidePop(); });
  app.graph.cy.on("viewport", hidePop);
  function hidePop() { pop.hidden = true; popPlace = null; }
  function updatePop() {
    if (!popPlace) return;
    document.getElementById("steer-count").textContent = String(live.marking[popPlace] || 0);
    const note = !app.control ? "read-only: open the console URL with its token to steer" : live.ended ? "the run has ended" :
      "control place: inserting or removing tokens changes the run's path (section 5)";
    document.getElementById("steer-note").textContent = note;
    for (const id of ["steer-insert", "steer-remove"]) document.getElementById(id).disabled = !app.control || live.ended;
  }
  async function steer(command) {
    if (!popPlace) return;
    const reply = await app.link.request("command", { command, place: popPlace, count: 1 });
    if (reply.ok) app.message(`${command} ${popPlace} 1: applied`, "ok");
    else app.message(`${command} ${popPlace} 1 refused: ${reply.reason}`, "bad");
    updatePop();
  }
  document.getElementById("steer-insert").addEventListener("click", () => steer("insert"));
  document.getElementById("steer-remove").addEventListener("click", () => steer("remove"));
  setInterval(updatePop, 300);

  for (const b of document.querySelectorAll("#live-bar button")) {
    b.setAttribute("data-title", b.title);
    b.addEventListener("click", async () => {
      const reply = await app.link.request("command", { command: b.dataset.cmd });
      if (reply.ok) app.message(`${b.dataset.cmd}: applied`, "ok");
      else app.message(`${b.dataset.cmd} refused: ${reply.reason}`, "bad");
    });
  }

  return { load, onFrame, paint, header, renderPanels, setHealth(h) { live.health = h; } };
}

/** The learner panel (section 4): per primitive task, each action's probability, trials, R, C and J. */
export function renderLearner(panel, learner) {
  const tasks = Object.entries(learner || {});
  panel.append(el("h3", {}, "Learning automata"));
  if (!tasks.length) { panel.append(el("p", { class: "empty" }, "no primitive task has learned yet")); return; }
  panel.append(el("p", { class: "small" }, "p: probability of choosing the action next; R: successes / trials; C: cost (a-priori or mean measured); J = 1 \u2212 R + \u03c1C, lower is better (paper sections 3 and 4)."));
  for (const [task, v] of tasks) {
    panel.append(el("p", { class: "subhead" }, el("b", {}, task), ` \u2014 ${v.scheme || "?"}, ${v.steps ?? 0} results, \u03c1 = ${fmt(v.rho)}`));
    const t = el("table", { class: "grid" }, el("tr", {}, ...["action", "p", "", "n", "R", "C", "J"].map((h) => el("th", {}, h))));
    const best = Math.min(...v.actions.filter((a) => a.J !== null).map((a) => a.J));
    for (const a of v.actions) {
      t.append(el("tr", {}, el("td", { class: "mono" }, a.name), el("td", { class: "num" }, fmt(a.p, 2)),
        el("td", {}, el("span", { class: "bar-p", style: { width: `${Math.round((a.p || 0) * 60)}px` } })),
        el("td", { class: "num" }, String(a.trials)), el("td", { class: "num" }, fmt(a.R)), el("td", { class: "num" }, fmt(a.C)),
        el("td", { class: "num" + (a.J !== null && a.J === best ? " node-ok" : "") }, fmt(a.J))));
    }
    panel.append(t);
  }
}
