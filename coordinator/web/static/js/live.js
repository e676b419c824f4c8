// Follow and steer a live run (paper section 5): frames from the server are applied as they arrive and
// drawn at most once per screen repaint, the latest marking winning; fired transitions flash; running
// actions and latched events sit beside their places; a primitive task whose last results were errors is
// marked red with its error branch, its last reason in full on hover or click; control places take token
// insertions and removals. The badge follows the run (running, paused, waiting, its end state), and once
// the run has ended the drawing keeps its final marking and the Run panel its summary.

import { el, fmt, seconds } from "./ui.js";

const END_STATES = new Set(["completed", "stuck", "waiting_for_operator", "aborted", "deadline", "interrupted"]);

// what the page measured, for bench/console.py: latency from firing (server clock) to the end of the
// paint that shows it, frames received and repaints showing firings
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
    offset: 0, ended: false, health: null, tasks: {}, summary: null,
  };
  app.live = live;
  let lastPanel = 0;

  // the server's node → {connected, heartbeat_rtt_s, in_flight}, as the health table reads it
  function toHealth(nodes) {
    if (!nodes) return null;
    const list = Object.entries(nodes).map(([node, h]) => ({ node, connected: h.connected, rtt_s: h.heartbeat_rtt_s,
                                                             in_flight: h.in_flight, used: h.used !== false }));
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
    live.tasks = snapshot.tasks || {};
    live.summary = snapshot.summary || null;
    live.offset = (snapshot.server_time || Date.now() / 1000) - Date.now() / 1000;
    live.ended = END_STATES.has(live.state.state);
    if (app.mode === "live") paint(true);
  }

  // Frames are applied as they arrive: tokens are small page elements and the page is drawn at most
  // once per screen frame, so the marking changes of several frames meet in one repaint, and a frame
  // that arrives just before a screen frame is drawn in it. The latency is measured after the paint:
  // a message posted from the frame's requestAnimationFrame callback runs once the page has been
  // styled, laid out and painted.
  let oldest = null;       // server time of the oldest firing applied but not yet painted
  let measuring = false;
  const afterPaint = new MessageChannel();
  afterPaint.port1.onmessage = (ev) => {
    stats.latencies[stats.n % stats.latencies.length] = (performance.timeOrigin + performance.now()) / 1000 - ev.data;
    stats.n++;
  };
  function measureNextPaint() {
    if (measuring) return;
    measuring = true;
    requestAnimationFrame(() => {
      measuring = false;
      stats.paints++;
      const shown = oldest;
      oldest = null;
      if (shown !== null) afterPaint.port2.postMessage(shown);
    });
  }
  let panelsDue = false;

  function onFrame(f) {
    stats.frames++;
    live.offset = f.t - Date.now() / 1000;
    if (f.marking) for (const [p, n] of Object.entries(f.marking)) { if (n) live.marking[p] = n; else delete live.marking[p]; }
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
    if (f.summary) live.summary = f.summary;
    if (f.tasks) Object.assign(live.tasks, f.tasks);
    if (f.nodes) live.health = toHealth(f.nodes);
    live.firings = f.firings;
    live.paused = f.paused;
    if (live.results.length > 40) live.results.splice(0, live.results.length - 40);
    if (live.errors.length > 20) live.errors.splice(0, live.errors.length - 20);
    if (live.operator.length > 20) live.operator.splice(0, live.operator.length - 20);
    live.ended = END_STATES.has(live.state.state);
    if (app.mode === "live") {
      if (f.marking) {
        app.graph.setMarking(f.marking);
        if (popPlace !== null && popPlace in f.marking) updatePop();  // the steering popover's count
      }
      if (f.fired) {
        app.graph.flash(Object.keys(f.fired));
        if (oldest === null) oldest = f.t_fired[0];
        measureNextPaint();
      }
      // badges only when actions started, ended or latched: a run firing thousands of transitions a
      // second redraws tokens and flashes, not the whole drawing's decorations
      if (f.tasks) markFailing();
      if (f.started || f.ended || f.latched || f.feedback) app.graph.setBadges(badges());
      if (f.tasks && taskPlace !== null) showTaskPop(taskPlace);
      if (f.started || f.ended || f.learner || f.operator || f.state || f.nodes || f.pulses || f.summary) panelsDue = true;
      scheduleText();
    }
    for (const o of f.operator || []) {
      const what = o.command === "invalid" ? `"${o.text}"` : [o.command, o.place, o.place ? o.count : null].filter((x) => x !== null).join(" ");
      if (!o.ok) app.message(`operator ${what} refused: ${o.reason}`, "bad");
    }
  }

  // the header and the side panels: DOM text, brought up to date once per screen frame at most
  let textScheduled = false;
  function scheduleText() {
    if (textScheduled) return;
    textScheduled = true;
    requestAnimationFrame(() => {
      textScheduled = false;
      if (app.mode !== "live") return;
      header();
      if (panelsDue) { panelsDue = false; renderPanelsSoon(true); }
    });
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
    for (const [place, rec] of failing().places) {
      if (map.has(place)) continue;
      const why = rec.last_error?.reason || "no reason given";
      map.set(place, { text: `\u2717 ${errorsInARow(rec)}: ${why.length > 60 ? why.slice(0, 59) + "\u2026" : why}`, failing: true });
    }
    return map;
  }

  // ------------------------------------------------------------------ primitive tasks that keep failing
  function errorsInARow(rec) { return `${rec.in_a_row} error${rec.in_a_row === 1 ? "" : "s"} in a row`; }

  /** The places and error branches of the primitive tasks whose last results were errors. */
  function failing() {
    const draft = app.liveNet?.draft;
    const places = new Map(), transitions = new Set();
    if (!draft) return { places, transitions };
    for (const rec of Object.values(live.tasks)) {
      if (!rec.in_a_row) continue;
      for (const p of draft.places) if (p.task === rec.task) places.set(p.id, rec);
      const error = `int:${rec.task}.error`;
      for (const t of draft.transitions) if ((t.events || []).includes(error)) transitions.add(t.id);
    }
    return { places, transitions };
  }

  function markFailing() {
    const f = failing();
    app.graph.setFailing([...f.places.keys()], [...f.transitions]);
  }

  function paintDetails(force) {
    markFailing();
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
  let countShownAt = 0;
  let countTimer = null;
  // the page is restyled only where a text really changed
  function setText(node, text) { if (node.textContent !== text) node.textContent = text; }
  function header() {
    const s = live.state.state || "";
    const state = document.getElementById("run-state");
    // the engine's pause holds while the run waits (for the operator to resume): the badge says paused
    const shown = live.ended ? s : live.paused ? "paused" : s === "started" || s === "resumed" ? "running" : s;
    setText(state, shown || " ");
    const cls = "run-state " + (END_STATES.has(s) ? (s === "completed" ? "ended" : "error") : shown);
    if (state.className !== cls) state.className = cls;
    // the firing count changes with every frame: shown ten times a second, and its last value always
    const now = performance.now();
    clearTimeout(countTimer);
    if (now - countShownAt >= 100 || live.paused || live.ended) {
      countShownAt = now;
      setText(document.getElementById("firings"), `${live.firings} firings`);
    } else {
      countTimer = setTimeout(() => { if (app.mode === "live") header(); }, 100 - (now - countShownAt));
    }
    const waiting = document.getElementById("waiting");
    setText(waiting, live.state.reason ? (live.ended ? `the run ended (${s}): ${live.state.reason}` : live.state.reason) : "");
    const detail = (live.state.detail || []).join("\n");
    if (waiting.title !== detail) waiting.title = detail;
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
    const shown = live.ended ? s.state : live.paused ? "paused" : s.state;
    panel.append(el("p", {}, el("b", {}, shown || "starting"), s.reason ? ` \u2014 ${s.reason}` : ""));
    if ((s.detail || []).length) panel.append(el("ul", { class: "small" }, ...s.detail.map((d) => el("li", {}, d))));
    if (live.summary) panel.append(summaryView(live.summary));
    const failingTasks = Object.values(live.tasks).filter((r) => r.in_a_row);
    if (failingTasks.length) {
      panel.append(el("h4", {}, "primitive tasks failing"));
      for (const r of failingTasks) {
        const e = r.last_error || {};
        panel.append(el("div", { class: "failing-task" }, el("b", {}, r.task), ` \u2014 ${errorsInARow(r)} (${r.errors} of ${r.results} results); last: `,
          el("span", { class: "mono" }, `${e.action || "?"} @ ${e.node || "not placed"}`), el("div", { class: "reason" }, e.reason || "no reason given")));
      }
    }
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
          el("td", { class: "small reason", title: r.reason || "" }, r.reason || "")));
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
    const unused = h.nodes.filter((n) => !n.used).map((n) => n.node);
    for (const n of h.nodes.filter((x) => x.used)) {
      t.append(el("tr", {}, el("td", {}, n.node), el("td", { class: n.connected ? "node-ok" : "node-bad" }, n.connected ? "connected" : "down"),
        el("td", { class: "num" }, n.rtt_s === null || n.rtt_s === undefined ? "-" : `${(n.rtt_s * 1000).toFixed(1)} ms`),
        el("td", { class: "num" }, String(n.in_flight ?? "-"))));
    }
    if (!unused.length) return t;
    return el("div", {}, t, el("p", { class: "small unused-nodes" },
      `not used by this net (none of its actions is placed there, none of its events comes from there): ${unused.join(", ")}`));
  }

  /** The summary of a run that has ended: how and why, firings, final marking, calls per action, errors. */
  function summaryView(sum) {
    const box = el("div", { class: "summary" }, el("h4", {}, "summary"),
      el("p", {}, `${sum.state} after ${sum.firings} firings`,
        sum.all_calls_failed ? el("span", { class: "node-bad" }, ` \u2014 every one of the ${sum.calls} primitive-action calls ended in error`) : ""),
      el("p", { class: "small mono" }, `final marking: ${Object.entries(sum.marking || {}).map(([p, n]) => `${p}: ${n}`).join(", ") || "no tokens"}`));
    if ((sum.actions || []).length) {
      const t = el("table", { class: "grid" }, el("tr", {}, ...["task/action", "node", "calls", "ok", "fail", "err", "mean"].map((h) => el("th", {}, h))));
      for (const a of sum.actions) {
        t.append(el("tr", {}, el("td", { class: "mono" }, `${a.task}/${a.action}`), el("td", {}, a.node || "-"),
          el("td", { class: "num" }, String(a.calls)), el("td", { class: "num" }, String(a.success)),
          el("td", { class: "num" }, String(a.failure)), el("td", { class: "num" + (a.error ? " node-bad" : "") }, String(a.error)),
          el("td", { class: "num" }, seconds(a.mean_s))));
      }
      box.append(t);
    }
    if (sum.n_errors) {
      box.append(el("p", { class: "small" }, `${sum.n_errors} error${sum.n_errors === 1 ? "" : "s"}${sum.n_errors > sum.errors.length ? `, the last ${sum.errors.length}` : ""}:`));
      box.append(el("ul", { class: "small reason" }, ...sum.errors.map((e) => el("li", {}, e))));
    }
    return box;
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
    if (place && place.task && showTaskPop(place.id, true)) { hidePop(); return; }
    if (!place || place.kind !== "control") { hidePop(); return; }
    popPlace = place.id;
    const rp = ev.target.renderedPosition();
    pop.style.left = `${rp.x + 30}px`;
    pop.style.top = `${Math.max(4, rp.y - 30)}px`;
    document.getElementById("steer-title").textContent = `${place.label || place.id}`;
    updatePop();
    pop.hidden = false;
  });
  app.graph.cy.on("tap", (ev) => { if (ev.target === app.graph.cy) { hidePop(); hideTaskPop(true); } });
  app.graph.cy.on("viewport", () => { hidePop(); hideTaskPop(true); });
  document.addEventListener("keydown", (ev) => {
    if (ev.key === "Escape" && !pop.hidden) hidePop();
    if (ev.key === "Escape") hideTaskPop(true);
  });

  // a primitive task's record (errors in a row, the last reason in full): on hover, kept by a click
  const taskPop = document.getElementById("task-pop");
  let taskPlace = null, taskPinned = false;
  function showTaskPop(placeId, pin = false) {
    const place = app.liveNet?.draft?.places.find((p) => p.id === placeId);
    const rec = place && live.tasks[place.task];
    if (!rec || !rec.errors) return false;
    const node = app.graph.cy.getElementById(placeId);
    if (node.empty()) return false;
    const rp = node.renderedPosition();
    taskPop.style.left = `${rp.x + 30}px`;
    taskPop.style.top = `${Math.max(4, rp.y - 30)}px`;
    const e = rec.last_error || {};
    document.getElementById("task-pop-title").textContent = `${rec.task}: ${rec.in_a_row ? errorsInARow(rec) : "last result not an error"}`;
    document.getElementById("task-pop-count").textContent =
      `${rec.errors} error${rec.errors === 1 ? "" : "s"} in ${rec.results} result${rec.results === 1 ? "" : "s"}; the last error: ` +
      `${e.action || "?"} on ${e.node || "no node"} at ${e.t ? new Date(e.t * 1000).toLocaleTimeString() : "?"}`;
    document.getElementById("task-pop-reason").textContent = e.reason || "no reason given";
    taskPop.hidden = false;
    taskPlace = placeId;
    if (pin) taskPinned = true;
    return true;
  }
  function hideTaskPop(unpin = false) {
    if (taskPinned && !unpin) return;
    taskPop.hidden = true;
    taskPlace = null;
    taskPinned = false;
  }
  app.graph.cy.on("mouseover", "node.place", (ev) => { if (app.mode === "live" && !taskPinned) showTaskPop(ev.target.id()); });
  app.graph.cy.on("mouseout", "node.place", () => hideTaskPop());
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
  panel.append(el("p", { class: "small" }, "p: probability of choosing the action next; R: successes / trials; C: cost (the net's a-priori cost, else the mean cost the action reported, or its wall time on the node, s); \u03c1: declared, else 1 / max C (one action: 1 / its deadline); J = 1 \u2212 R + \u03c1C, lower is better (paper sections 3 and 4; petrobot perf and learn use the same C and \u03c1)."));
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
