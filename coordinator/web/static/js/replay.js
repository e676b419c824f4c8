// Replay a run from the journal (paper section 5): scrub back and forth through its records, see the
// marking, the running actions and the latched events at any point, jump to errors. What the
// operator did shows as theirs: forced outcomes are marked "forced by the operator", injected events
// "raised by the operator", and the breakpoints set at each point are drawn as on the live page, with
// the pauses they made.

import { api } from "./ws.js";
import { clock, el, seconds } from "./ui.js";
import { renderLearner } from "./live.js";

const CHECKPOINT = 256;

function latchedEvents(task, status, outcome) {
  const out = status === "error" ? ["error"] : ["ok", status];
  if (outcome) out.push(outcome);
  return out.map((o) => `int:${task}.${o}`);
}

export function initReplay(app) {
  const rp = { data: null, records: [], k: 0, checkpoints: [], errors: [], playing: false, timer: null, runs: [] };
  app.replay = rp;
  const slider = document.getElementById("rp-slider");

  // ------------------------------------------------------------------ the runs list
  async function loadRuns() {
    const panel = document.getElementById("panel-timeline");
    panel.replaceChildren(el("p", { class: "small" }, "reading the journal..."));
    let data;
    try { data = await api("/api/runs", app.token); }
    catch (e) { panel.replaceChildren(el("p", { class: "node-bad" }, String(e.message || e))); return; }
    rp.runs = data.runs;
    rp.live = data.live;
    rp.journal = data.journal;
    renderRuns(data);
  }
  app.loadRuns = loadRuns;

  function renderRuns(data) {
    const panel = document.getElementById("panel-timeline");
    panel.replaceChildren();
    panel.append(el("h3", {}, "Runs"), el("p", { class: "small" }, data.journal ? `journal ${data.journal}` : "no journal"));
    if (!data.journal) { panel.append(el("p", { class: "empty" }, "start the console with --journal FILE to replay runs")); return; }
    const refresh = el("button", {}, "\u21BB refresh");
    refresh.addEventListener("click", loadRuns);
    panel.append(refresh);
    const list = el("ul", { class: "runs-list" });
    for (const r of data.runs) {
      const live = r.id === data.live;
      const li = el("li", { class: rp.data?.run.id === r.id ? "current" : "" },
        el("b", {}, r.id), ` ${r.net} \u00b7 `, live ? el("b", { class: "node-ok" }, "live") : (r.state || "unfinished"),
        el("div", { class: "small" }, `${new Date(r.started * 1000).toLocaleString()} \u00b7 ${seconds(r.duration_s)} \u00b7 ` +
          `${r.firings} firings, ${r.calls} calls, ${r.errors} errors`));
      li.addEventListener("click", () => open(r.id));
      list.append(li);
    }
    if (!data.runs.length) list.append(el("li", { class: "empty" }, "no runs in this journal"));
    panel.append(list);
    panel.append(el("div", { id: "rp-records" }));
    if (rp.data) renderRecords();
  }

  // ------------------------------------------------------------------ one run
  async function open(runId) {
    stop();
    app.message(`reading run ${runId}...`);
    let data;
    try { data = await api(`/api/replay?run=${encodeURIComponent(runId)}`, app.token); }
    catch (e) { app.message(String(e.message || e), "bad"); return; }
    if (!data.draft) { app.message("this run did not store its net, and no open net has its name", "bad"); return; }
    rp.data = data;
    rp.records = data.records;
    rp.errors = rp.records.map((r, i) => (r[0] === "r" && r[5] === "error" ? i + 1 : -1)).filter((i) => i > 0);
    buildCheckpoints();
    slider.max = String(rp.records.length);
    app.replayDraft = data.draft;
    app.setMode("replay");
    app.graph.fit();  // the run's net, whole (the view may have been fitted to an empty one)
    seek(0);  // a replay starts where the run started
    app.message(`run ${runId}: ${rp.records.length} records, ${rp.errors.length} errors; shown at its start: ` +
                "\u25B6 plays it, the slider and the arrow keys step through it, \u25B6| goes to its end");
    for (const n of data.notes || []) app.message(n);
    if (rp.runs.length) renderRuns({ journal: rp.journal, runs: rp.runs, live: rp.live });
  }
  app.openReplay = open;

  function emptyState() {
    return { marking: { ...rp.data.initial }, running: new Map(), latched: new Map(), firings: 0, breakpoints: new Map(), hit: null };
  }
  function bpKey(bp) { return `${bp.kind} ${bp.target}${bp.kind === "count" ? " " + bp.count : ""}`; }
  function step(s, r) {
    if (r[0] === "f") {
      for (const [p, n] of Object.entries(r[3])) s.marking[p] = (s.marking[p] || 0) - n;
      for (const [p, n] of Object.entries(r[4])) s.marking[p] = (s.marking[p] || 0) + n;
      for (const i of r[7] || []) s.latched.delete(i);
      s.firings = r[1];
    } else if (r[0] === "s") {
      s.running.set(r[1], { i: r[1], task: r[2], place: r[3], action: r[4], node: r[5], t: r[6] });
    } else if (r[0] === "r") {
      const run = s.running.get(r[1]);
      s.running.delete(r[1]);
      if (run) s.latched.set(r[1], { place: run.place, action: r[3], events: latchedEvents(r[2], r[5], r[6]), status: r[5], forced: !!r[10] });
    } else if (r[0] === "o" && r[4] && (r[1] === "insert" || r[1] === "remove") && r[2]) {
      s.marking[r[2]] = (s.marking[r[2]] || 0) + (r[3] || 0) * (r[1] === "insert" ? 1 : -1);
    } else if (r[0] === "o" && r[4] && r[7] && r[7].breakpoint) {
      const bp = r[7].breakpoint;
      if (r[1] === "break") s.breakpoints.set(bpKey(bp), bp);
      else if (r[1] === "clear") s.breakpoints.delete(bpKey(bp));
      else if (r[1] === "pause") s.hit = { ...bp, why: r[7].why };
    } else if (r[0] === "o" && r[4] && (r[1] === "resume" || r[1] === "step")) {
      s.hit = null;
    }
  }
  function copy(s) {
    return { marking: { ...s.marking }, running: new Map(s.running), latched: new Map(s.latched), firings: s.firings,
             breakpoints: new Map(s.breakpoints), hit: s.hit };
  }
  function buildCheckpoints() {
    rp.checkpoints = [];
    const s = emptyState();
    rp.records.forEach((r, i) => { if (i % CHECKPOINT === 0) rp.checkpoints.push(copy(s)); step(s, r); });
    if (rp.records.length % CHECKPOINT === 0) rp.checkpoints.push(copy(s));
  }
  function stateAt(k) {
    const c = Math.floor(k / CHECKPOINT);
    const s = copy(rp.checkpoints[Math.min(c, rp.checkpoints.length - 1)]);
    for (let i = Math.min(c, rp.checkpoints.length - 1) * CHECKPOINT; i < k; i++) step(s, rp.records[i]);
    return s;
  }

  function seek(k) {
    if (!rp.data) return;
    rp.k = Math.max(0, Math.min(k, rp.records.length));
    slider.value = String(rp.k);
    if (app.mode !== "replay") return;
    const s = stateAt(rp.k);
    rp.state = s;
    const marking = {};
    for (const [p, n] of Object.entries(s.marking)) if (n) marking[p] = n;
    app.graph.setMarking(marking, true);
    const last = rp.records[rp.k - 1];
    if (last && last[0] === "f") app.graph.flash([last[2]]);
    const badges = new Map();
    const t = last ? lastTime(rp.k) : rp.data.run.started;
    for (const r of s.running.values()) {
      const prev = badges.get(r.place);
      const line = `\u25B6 ${r.action} @ ${r.node || "not placed"}  ${seconds(Math.max(0, t - r.t))}`;
      badges.set(r.place, { text: prev ? prev.text + "\n" + line : line, latched: false });
    }
    for (const l of s.latched.values()) {
      if (badges.has(l.place)) continue;
      badges.set(l.place, { text: `${l.status === "error" ? "\u2717" : "\u2713"} ${l.events.join(" ")} (${l.action})${l.forced ? " FORCED by the operator" : ""}`,
                            latched: true });
    }
    app.graph.setBadges(badges);
    const marks = [];
    const placesOf = (task) => (rp.data.draft.places || []).filter((p) => p.task === task).map((p) => p.id);
    for (const bp of s.breakpoints.values()) {
      for (const node of bp.kind === "error" ? placesOf(bp.target) : [bp.target]) {
        const hit = s.hit && bpKey(s.hit) === bpKey(bp);
        marks.push({ key: `bp:${bpKey(bp)}:${node}`, node, at: "corner-right", cls: "bp" + (hit ? " hit" : ""),
                     text: { enabled: "E", fires: "F", count: "#", error: "!" }[bp.kind],
                     title: `breakpoint ${bpKey(bp)}${hit ? ` \u2014 the run paused here: ${s.hit.why}` : ""}` });
      }
    }
    app.graph.setMarks("breakpoints", marks);
    header(s, last);
    renderRecords();
    renderRunPanel(s, last);
  }
  app.replaySeek = () => seek(rp.k);
  rp.seek = (k) => { stop(); seek(k); };

  function lastTime(k) {
    const r = rp.records[k - 1];
    return r[0] === "f" ? r[5] : r[0] === "s" ? r[6] : r[0] === "r" ? r[9] : r[6];
  }

  function describe(r) {
    switch (r[0]) {
      case "f": return `fire #${r[1]} ${r[2]}${r[6] ? " on " + r[6] : ""}   ${places(r[3])} \u2192 ${places(r[4])}`;
      case "s": return `start ${r[2]} \u2192 ${r[4]} on ${r[5] || "?"}`;
      case "r": return r[10] ? `FORCED ${r[2]}/${r[3]}: ${r[5]}${r[6] ? " (" + r[6] + ")" : ""}${r[7] ? ": " + r[7] : ""}`
        : `done ${r[2]}/${r[3]}: ${r[5]}${r[6] ? " (" + r[6] + ")" : ""} in ${seconds(r[8])}${r[7] ? ": " + r[7] : ""}`;
      default: return `operator ${r[1]}${r[2] ? " " + r[2] + " " + r[3] : ""}${detail(r[1], r[7])}${r[4] ? "" : " refused: " + (r[5] || "")}`;
    }
  }
  function detail(command, d) {
    if (!d) return "";
    if (d.breakpoint) return command === "pause" ? ` at breakpoint ${bpKey(d.breakpoint)}: ${d.why || ""}` : ` ${bpKey(d.breakpoint)}`;
    if (d.event) {
      const payload = d.payload === undefined || d.payload === null ? "" : ` ${JSON.stringify(d.payload)}`;
      return ` ${d.event}${payload.length > 81 ? `${payload.slice(0, 80)}…` : payload} (raised by the operator)`;
    }
    if (d.instance) return ` ${d.outcome} on ${d.instance}${d.reason ? ` (${d.reason})` : ""}`;
    return "";
  }
  function places(m) { return Object.entries(m).map(([p, n]) => (n === 1 ? p : `${p}\u00d7${n}`)).join(", ") || "-"; }

  function header(s, last) {
    const run = rp.data.run;
    const state = document.getElementById("run-state");
    state.textContent = rp.k === rp.records.length ? (run.state || "unfinished") : "replay";
    state.className = "run-state " + (rp.k === rp.records.length ? (run.state === "completed" ? "ended" : run.state ? "error" : "waiting") : "paused");
    document.getElementById("firings").textContent = `${s.firings} firings`;
    const t0 = run.started;
    const at = last ? lastTime(rp.k) : t0;
    document.getElementById("rp-pos").textContent = `${rp.k} / ${rp.records.length} records \u00b7 ${clock(at)} (+${seconds(at - t0)})`;
  }

  function renderRecords() {
    const box = document.getElementById("rp-records");
    if (!box || !rp.data) return;
    box.replaceChildren(el("h4", {}, `run ${rp.data.run.id}: records around the cursor`));
    const from = Math.max(0, rp.k - 12), to = Math.min(rp.records.length, rp.k + 12);
    for (let i = from; i < to; i++) {
      const r = rp.records[i];
      const cls = "rec" + (i === rp.k - 1 ? " here" : "") + (r[0] === "r" && r[5] === "error" ? " err" : "") + (r[0] === "o" ? " op" : "")
        + (r[0] === "r" && r[10] ? " forced" : "") + (r[0] === "o" && r[7] && r[7].breakpoint && r[1] === "pause" ? " bp" : "");
      const row = el("div", { class: cls, title: describe(r) }, `${String(i + 1).padStart(5)} ${describe(r)}`);
      row.addEventListener("click", () => seek(i + 1));
      box.append(row);
    }
    if (rp.data.run.note) box.append(el("p", { class: "small" }, `end: ${rp.data.run.note}`));
  }

  function renderRunPanel(s, last) {
    const panel = document.getElementById("panel-run");
    panel.replaceChildren(el("h3", {}, `Replay of run ${rp.data.run.id}`),
      el("p", {}, last ? describe(last) : "the start of the run"));
    panel.append(el("h4", {}, "running primitive actions"));
    if (!s.running.size) panel.append(el("p", { class: "empty" }, "none"));
    else panel.append(el("ul", { class: "mono" }, ...[...s.running.values()].map((r) => el("li", {}, `${r.place}: ${r.action} on ${r.node || "?"} (${r.i})`))));
    panel.append(el("h4", {}, "latched events"));
    if (!s.latched.size) panel.append(el("p", { class: "empty" }, "none"));
    else panel.append(el("ul", { class: "mono" }, ...[...s.latched.entries()].map(([i, l]) => el("li", {}, `${l.place}: ${l.events.join(", ")} (${l.action}, ${i})`))));
    const learning = document.getElementById("panel-learning");
    learning.replaceChildren();
    if (rp.data.learner) renderLearner(learning, rp.data.learner);
    else learning.append(el("p", { class: "empty" }, "the learners' state is shown for live runs"));
  }

  // ------------------------------------------------------------------ controls
  slider.addEventListener("input", () => { stop(); seek(Number(slider.value)); });
  document.getElementById("rp-start").addEventListener("click", () => { stop(); seek(0); });
  document.getElementById("rp-end").addEventListener("click", () => { stop(); seek(rp.records.length); });
  document.getElementById("rp-prev").addEventListener("click", () => { stop(); seek(rp.k - 1); });
  document.getElementById("rp-next").addEventListener("click", () => { stop(); seek(rp.k + 1); });
  document.getElementById("rp-next-error").addEventListener("click", () => {
    stop();
    const next = rp.errors.find((i) => i > rp.k);
    if (next) seek(next); else app.message("no error after this point");
  });
  document.getElementById("rp-prev-error").addEventListener("click", () => {
    stop();
    const prev = [...rp.errors].reverse().find((i) => i < rp.k);
    if (prev) seek(prev); else app.message("no error before this point");
  });
  document.getElementById("rp-play").addEventListener("click", () => (rp.playing ? stop() : play()));
  document.addEventListener("keydown", (ev) => {
    if (app.mode !== "replay" || ["INPUT", "SELECT", "TEXTAREA"].includes(document.activeElement?.tagName)) return;
    if (ev.key === "ArrowLeft") { stop(); seek(rp.k - 1); }
    if (ev.key === "ArrowRight") { stop(); seek(rp.k + 1); }
    if (ev.key === " ") { ev.preventDefault(); rp.playing ? stop() : play(); }
  });

  function play() {
    if (!rp.data) return;
    if (rp.k >= rp.records.length) seek(0);
    rp.playing = true;
    document.getElementById("rp-play").textContent = "\u2016";
    tick();
  }
  function tick() {
    if (!rp.playing) return;
    if (rp.k >= rp.records.length) { stop(); return; }
    const speed = Number(document.getElementById("rp-speed").value);
    const gap = rp.k > 0 ? lastTime(rp.k + 1) - lastTime(rp.k) : 0;
    const delay = speed === 0 ? 350 : Math.min(1000, Math.max(0, gap * 1000 / speed));
    rp.timer = setTimeout(() => { seek(rp.k + 1); tick(); }, delay);
  }
  function stop() {
    rp.playing = false;
    clearTimeout(rp.timer);
    document.getElementById("rp-play").textContent = "\u25B6";
  }

  return { loadRuns, open, seek };
}
