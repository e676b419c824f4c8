// Follow and steer a live run (paper section 5): frames from the server are applied as they arrive and
// drawn at most once per screen repaint, the latest marking winning, and the page says when it has
// painted one (the server sizes its frames to that); fired transitions flash; running actions and
// latched events sit beside their places; a primitive task whose last results were errors is marked
// red with its error branch, its last reason in full on hover; control places take token insertions
// and removals. A click on any other place or transition sets breakpoints on it (journaled like any
// command, drawn as red dots) and, on a primitive task's place, forces the outcome of its running
// action and opens its blackboard (parameters, feedback, latched results and their payloads), where
// the net's [operator] table allows; the bar raises its external events. The badge follows the run
// (running, paused, waiting, its end state), and once the run has ended the drawing keeps its final
// marking and the Run panel its summary.

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
    offset: 0, ended: false, health: null, tasks: {}, summary: null, breakpoints: [], hits: [], injected: [],
    blackboard: null, blackboardPlace: null,
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
    live.breakpoints = snapshot.breakpoints || [];
    live.hits = snapshot.hits || [];
    live.offset = (snapshot.server_time || Date.now() / 1000) - Date.now() / 1000;
    live.ended = END_STATES.has(live.state.state);
    if (live.runId !== live.blackboardRun) { live.blackboard = null; live.blackboardPlace = null; }
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
      painted.port2.postMessage(lastSeq);
    });
  }
  // once a repaint has shown the frames received so far, the server may send the next one
  let lastSeq = 0;
  const painted = new MessageChannel();
  painted.port1.onmessage = (ev) => app.link.notify("painted", { seq: ev.data });
  let panelsDue = false;

  function onFrame(f) {
    stats.frames++;
    lastSeq = f.seq;
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
    if (f.breakpoints) live.breakpoints = f.breakpoints;
    for (const h of f.hits || []) {
      live.hits.push(h);
      app.message(`paused at breakpoint ${h.text}: ${h.why}`, "bad");
      document.body.dataset.hit = h.text;
    }
    for (const i of f.injected || []) {
      live.injected.push(i);
      app.message(`operator raised ${i.event}: ${i.fired} transition${i.fired === 1 ? "" : "s"} fired`, "ok");
    }
    if (live.injected.length > 20) live.injected.splice(0, live.injected.length - 20);
    if (live.hits.length > 20) live.hits.splice(0, live.hits.length - 20);
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
      }
      measureNextPaint();  // and then tell the server this frame is painted
      // badges only when actions started, ended or latched: a run firing thousands of transitions a
      // second redraws tokens and flashes, not the whole drawing's decorations
      if (f.tasks) markFailing();
      if (f.started || f.ended || f.latched || f.feedback) app.graph.setBadges(badges());
      if (f.breakpoints || f.hits) markBreakpoints();
      if (f.learner) app.redrawAnalysis();
      if (live.blackboardPlace && (f.started || f.ended || f.feedback || f.latched || f.injected || f.pulses)) blackboardSoon();
      if (nodePlace !== null && (f.started || f.ended || f.breakpoints)) renderNodePop();
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
    markBreakpoints();
    header();
    inject();
    if (force) renderPanelsSoon(false);
  }

  // ------------------------------------------------------------------ breakpoints (coordinator/breakpoints.py)
  const BP_TEXT = { enabled: "pause when it becomes ready to fire", fires: "pause right after it fires",
                    count: "pause when it reaches", error: "pause when its task ends with an error" };
  function bpText(bp) { return `${bp.kind} ${bp.target}${bp.kind === "count" ? " " + bp.count : ""}`; }
  function markBreakpoints() {
    const last = live.hits[live.hits.length - 1];
    const placeOfTask = (task) => (app.liveNet?.draft?.places || []).filter((p) => p.task === task).map((p) => p.id);
    const marks = [];
    for (const bp of live.breakpoints) {
      const nodes = bp.kind === "error" ? placeOfTask(bp.target) : [bp.target];
      for (const node of nodes) {
        const hit = live.paused && last && last.kind === bp.kind && last.target === bp.target;
        marks.push({ key: `bp:${bpText(bp)}:${node}`, node, at: "corner-right", cls: "bp" + (hit ? " hit" : ""),
                     text: { enabled: "E", fires: "F", count: "#", error: "!" }[bp.kind],
                     title: `breakpoint ${bpText(bp)}: ${BP_TEXT[bp.kind]}${bp.kind === "count" ? " " + bp.count + " tokens" : ""}` +
                            (app.control && !live.ended ? " (click to clear it)" : ""),
                     onclick: () => { if (app.control && !live.ended) command("clear", { breakpoint: bp }); } });
      }
    }
    app.graph.setMarks("breakpoints", marks);
  }
  app.breakpointText = bpText;

  async function command(name, fields = {}) {
    const reply = await app.link.request("command", { command: name, ...fields });
    const what = reply.command || name;
    if (reply.ok) app.message(`${what}: applied`, "ok");
    else app.message(`${what} refused: ${reply.reason}`, "bad");
    return reply;
  }
  app.command = command;

  // ------------------------------------------------------------------ raising an external event (the net's [operator] inject)
  function inject() {
    const allowed = app.liveNet?.draft?.operator?.inject || [];
    const box = document.getElementById("inject-box");
    box.hidden = !allowed.length || app.mode !== "live";
    const select = document.getElementById("inject-event");
    const key = allowed.join(",");
    if (select.dataset.key !== key) {
      select.replaceChildren(...allowed.map((e) => el("option", { value: e }, e)));
      select.dataset.key = key;
    }
    const off = !app.control || live.ended;
    select.disabled = off;
    document.getElementById("inject-go").disabled = off;
    document.getElementById("inject-payload").disabled = off;
  }
  document.getElementById("inject-go").addEventListener("click", () => {
    const event = document.getElementById("inject-event").value;
    const box = document.getElementById("inject-payload");
    const text = box.value.trim();
    let payload = null;
    if (text) {
      try { payload = JSON.parse(text); } catch (err) {
        box.setCustomValidity("not JSON");
        box.title = `the payload must be JSON: ${err.message}`;
        box.reportValidity();
        return;
      }
    }
    box.setCustomValidity("");
    box.title = "the event's payload, as JSON (optional)";
    if (event) command("inject", payload === null ? { event } : { event, payload });
  });

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
    for (const b of document.querySelectorAll("#live-bar button[data-cmd]")) {
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
          el("td", { class: cls }, r.status + (r.outcome ? ` (${r.outcome})` : ""), r.forced ? el("span", { class: "forced", title: "forced by the operator: no measured result" }, " forced") : ""),
          el("td", { class: "num" }, seconds(r.wall_s)),
          el("td", { class: "small reason", title: r.reason || "" }, r.reason || "")));
      }
      panel.append(t);
    }
    if (live.operator.length) {
      panel.append(el("h4", {}, "operator commands"));
      panel.append(el("ul", { class: "small" }, ...live.operator.slice(-8).reverse().map((o) => el("li", { class: o.ok ? "" : "node-bad" },
        `${o.command === "invalid" ? `"${o.text}"` : o.text || o.command}: ${o.ok ? "applied" : "refused: " + o.reason}`))));
    }
    const pulses = Object.entries(live.pulses);
    if (pulses.length) panel.append(el("p", { class: "small" }, "external events: " + pulses.map(([e, n]) => `${e} \u00d7${n}`).join(", ")));
    panel.append(el("h4", {}, "breakpoints"));
    if (!live.breakpoints.length) panel.append(el("p", { class: "empty" }, "none: click a place or a transition to set one"));
    else panel.append(el("ul", { class: "mono small" }, ...live.breakpoints.map((bp) => el("li", {}, bpText(bp)))));
    if (live.hits.length) {
      const h = live.hits[live.hits.length - 1];
      panel.append(el("p", { class: "small node-bad" }, `last stop: ${h.text} (${h.why})`));
    }
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
  app.graph.cy.on("tap", "node", (ev) => {
    if (app.mode !== "live") return;
    const draft = app.currentDraft();
    const place = draft?.places.find((p) => p.id === ev.target.id());
    hideTaskPop(true);
    if (!place || place.kind !== "control") {
      hidePop();
      showNodePop(ev.target.id());
      return;
    }
    hideNodePop();
    popPlace = place.id;
    const rp = ev.target.renderedPosition();
    pop.style.left = `${rp.x + 30}px`;
    pop.style.top = `${Math.max(4, rp.y - 30)}px`;
    document.getElementById("steer-title").textContent = `${place.id}${place.label ? " \u2014 " + place.label : ""}`;
    updatePop();
    pop.hidden = false;
  });
  app.graph.cy.on("tap", (ev) => { if (ev.target === app.graph.cy) { hidePop(); hideTaskPop(true); hideNodePop(); } });
  app.graph.cy.on("viewport", () => { hidePop(); hideTaskPop(true); hideNodePop(); });
  document.addEventListener("keydown", (ev) => {
    if (ev.key === "Escape" && !pop.hidden) hidePop();
    if (ev.key === "Escape") { hideTaskPop(true); hideNodePop(); }
  });

  // a place's or transition's breakpoints, a running action's forced outcome, the blackboard
  const nodePop = document.getElementById("node-pop");
  let nodePlace = null;
  function showNodePop(id) {
    nodePlace = id;
    const node = app.graph.cy.getElementById(id);
    const rp = node.renderedPosition();
    nodePop.style.left = `${rp.x + 30}px`;
    nodePop.style.top = `${Math.max(4, rp.y - 30)}px`;
    renderNodePop();
    nodePop.hidden = false;
  }
  function hideNodePop() { nodePop.hidden = true; nodePlace = null; }
  app.showNodePop = showNodePop;

  function bpToggle(bp, label) {
    const set = live.breakpoints.some((b) => b.kind === bp.kind && b.target === bp.target && (b.count ?? null) === (bp.count ?? null));
    const box = el("input", { type: "checkbox", "data-bp": bp.kind });
    box.checked = set;
    box.disabled = !app.control || live.ended;
    box.addEventListener("change", () => command(box.checked ? "break" : "clear", { breakpoint: bp }));
    return el("label", { class: "bp-row" }, box, label);
  }

  function renderNodePop() {
    if (nodePlace === null) return;
    const draft = app.currentDraft();
    const id = nodePlace;
    const place = draft?.places.find((p) => p.id === id);
    const transition = draft?.transitions.find((t) => t.id === id);
    const parts = [el("div", { class: "pop-title" }, place ? `place ${id}` : `transition ${id}`)];
    if (transition) {
      parts.push(el("div", { class: "small mono" }, (transition.events || []).join(", ") || "no event"));
      parts.push(el("h5", {}, "breakpoints"), bpToggle({ kind: "enabled", target: id, count: null }, BP_TEXT.enabled),
                 bpToggle({ kind: "fires", target: id, count: null }, BP_TEXT.fires));
    } else if (place) {
      const set = live.breakpoints.find((b) => b.kind === "count" && b.target === id);
      const n = el("input", { type: "number", min: "0", value: String(set ? set.count : (live.marking[id] || 0) + 1), "data-count": id });
      const setBtn = el("button", {}, set ? "clear" : "set");
      setBtn.disabled = !app.control || live.ended;
      setBtn.addEventListener("click", () => {
        if (set) command("clear", { breakpoint: set });
        else command("break", { breakpoint: { kind: "count", target: id, count: Math.max(0, Math.trunc(Number(n.value) || 0)) } });
      });
      parts.push(el("h5", {}, "breakpoints"), el("div", { class: "bp-row" }, `${BP_TEXT.count} `, n, " tokens ", setBtn));
      if (place.task) {
        parts.push(bpToggle({ kind: "error", target: place.task, count: null }, BP_TEXT.error));
        const allowed = draft.operator?.force?.[place.task] || [];
        const running = [...live.running.values()].filter((r) => r.place === id);
        if (allowed.length && running.length) {
          parts.push(el("h5", {}, "force the outcome (a drill)"));
          const why = el("input", { type: "text", placeholder: "reason (journaled)", size: 18, id: "force-reason" });
          parts.push(why);
          for (const r of running) {
            const row = el("div", { class: "bp-row" }, el("span", { class: "mono small" }, `${r.action} [${r.i}]`));
            for (const o of allowed) {
              const b = el("button", { "data-outcome": o, title: `end ${r.action} now with ${o}, as the operator (never counted as measured reliability)` }, o);
              b.disabled = !app.control || live.ended;
              b.addEventListener("click", () => command("force", { instance: r.i, outcome: o, reason: why.value.trim() }));
              row.append(b);
            }
            parts.push(row);
          }
        } else if (allowed.length) {
          parts.push(el("p", { class: "pop-note" }, `the operator may force ${allowed.join(", ")} on ${place.task} while it runs`));
        }
        const bb = el("button", {}, "blackboard");
        bb.addEventListener("click", () => openBlackboard(id));
        parts.push(el("p", {}, bb));
        const rec = live.tasks[place.task];
        if (rec && rec.errors) {
          const e = rec.last_error || {};
          parts.push(el("h5", {}, `${rec.in_a_row ? errorsInARow(rec) : "errors"} (${rec.errors} of ${rec.results})`),
                     el("div", { class: "reason small node-bad" }, `${e.action || "?"} on ${e.node || "no node"}: ${e.reason || "no reason given"}`));
        }
      }
    }
    if (!app.control) parts.push(el("p", { class: "pop-note" }, "read-only: open the console URL with its token to set breakpoints"));
    nodePop.replaceChildren(...parts);
  }

  // ------------------------------------------------------------------ the blackboard of a place (what its actions are doing)
  let bbTimer = null, bbBusy = false;
  function blackboardSoon() {
    if (bbTimer) return;
    bbTimer = setTimeout(() => { bbTimer = null; loadBlackboard(); }, 150);
  }
  async function loadBlackboard() {
    if (!live.blackboardPlace || bbBusy) return;
    bbBusy = true;
    const reply = await app.link.request("blackboard", { place: live.blackboardPlace });
    bbBusy = false;
    if (reply.ok) { live.blackboard = reply.blackboard; live.blackboardRun = live.runId; renderBlackboard(); }
  }
  function openBlackboard(place) {
    live.blackboardPlace = place;
    hideNodePop();
    app.selectTab("blackboard");
    loadBlackboard();
  }
  app.openBlackboard = openBlackboard;
  setInterval(() => {
    if (app.mode === "live" && live.blackboardPlace && document.getElementById("panel-blackboard").classList.contains("active")) loadBlackboard();
  }, 1000);

  function json(value) { return el("pre", { class: "json" }, value === null || value === undefined ? "null" : JSON.stringify(value, null, 1)); }
  function renderBlackboard() {
    const panel = document.getElementById("panel-blackboard");
    panel.replaceChildren();
    const b = live.blackboard;
    if (!b) { panel.append(el("h3", {}, "Blackboard"), el("p", { class: "empty" }, "click a primitive task's place, then blackboard")); return; }
    panel.append(el("h3", {}, `Blackboard of ${b.place}${b.task ? ` (${b.task})` : ""}`));
    panel.append(el("h4", {}, "running"));
    if (!b.running.length) panel.append(el("p", { class: "empty" }, "no action running"));
    const now = nowServer();
    for (const r of b.running) {
      panel.append(el("p", {}, el("b", { class: "mono" }, r.action), ` on ${r.node || "not placed"} for ${seconds(now - r.t)} [${r.i}]`));
      panel.append(el("div", { class: "small" }, "parameters"), json(r.params));
      panel.append(el("div", { class: "small" }, `feedback (${r.feedback_count} received${r.feedback_t ? `, the latest ${seconds(Math.max(0, now - r.feedback_t))} ago` : ""})`),
                   json(r.feedback));
    }
    panel.append(el("h4", {}, "latched results (waiting for a transition)"));
    if (!b.latched.length) panel.append(el("p", { class: "empty" }, "none"));
    for (const l of b.latched) {
      panel.append(el("p", {}, el("span", { class: "mono" }, l.events.join(" ")), ` \u2014 ${l.action}: ${l.status || "?"}${l.outcome ? ` (${l.outcome})` : ""}`,
        l.forced ? el("span", { class: "forced" }, " forced by the operator") : "", l.reason ? el("div", { class: "small reason" }, l.reason) : ""));
      panel.append(el("div", { class: "small" }, "payload (the returned value)"), json(l.value));
    }
    panel.append(el("h4", {}, "external events, latest first"));
    if (!b.events.length) panel.append(el("p", { class: "empty" }, "none yet"));
    else panel.append(el("ul", { class: "mono small" }, ...b.events.map((e) => el("li", {},
      `${e.event} ${seconds(Math.max(0, now - e.t))} ago: ${e.fired} fired${e.operator ? " (raised by the operator)" : ""}`,
      e.payload === null || e.payload === undefined ? el("div", { class: "small" }, "no payload")
        : el("div", { class: "event-payload" }, el("div", { class: "small" }, "payload"), json(e.payload))))));
  }

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

  for (const b of document.querySelectorAll("#live-bar button[data-cmd]")) {
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
