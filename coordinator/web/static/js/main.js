// The console page: modes (design, live, replay), the connection, files, the runs it follows, and the
// glue between panels.

import { Graph, nextLabelMode } from "./graph.js";
import { History, clone, emptyDraft, findNode } from "./net.js";
import { initEditor } from "./editor.js";
import { initLive } from "./live.js";
import { initReplay } from "./replay.js";
import { renderProblems } from "./panels.js";
import { initAnalysis } from "./analysis.js";
import { initRuns } from "./runs.js";
import { Link, api } from "./ws.js";
import { el } from "./ui.js";

const params = new URLSearchParams(location.search);
const token = params.get("token");

const app = {
  token, control: false, mode: "design", servicesKnown: false, validation: null,
  design: { draft: null, path: null, history: new History(), dirty: false, saved: null },
  liveNet: null, replayDraft: null, journal: null, nets: [], definitions: {}, runs: [],
  wantRun: params.get("run"),
};
window.petrobot = app;  // for the browser tests and bench/console.py

app.graph = new Graph(document.getElementById("cy"));

// ------------------------------------------------------------------ messages
let messageTimer = null;
app.message = (text, kind = "") => {
  const m = document.getElementById("message");
  m.textContent = text;
  m.className = "message " + kind;
  clearTimeout(messageTimer);
  messageTimer = setTimeout(() => { if (m.textContent === text) { m.textContent = ""; m.className = "message"; } }, 9000);
};
app.hint = (text) => { document.getElementById("hint").textContent = text; };
/** The documentation page and section defining a kind of number (welcome's definitions). */
app.doc = (kind) => (app.definitions[kind] ? `/docs/${app.definitions[kind]}` : null);

// ------------------------------------------------------------------ drafts and modes
app.currentDraft = () => (app.mode === "design" ? app.design.draft : app.mode === "live" ? app.liveNet?.draft : app.replayDraft);

function redraw({ fit = false } = {}) {
  const draft = app.currentDraft();
  if (!draft) { app.graph.sync(emptyDraft()); return; }
  const marking = app.mode === "live" && app.live ? { ...app.live.marking } : null;
  app.graph.sync(draft, { marking, fit });
  if (app.mode === "design") app.graph.setBadges(new Map());
  else if (app.mode === "live") liveView.paint(false);
  else app.replaySeek && app.replaySeek();
  analysis.redraw();
  document.getElementById("net-name").textContent = draft.net?.name || "untitled";
  updateDirty();
}
app.redraw = redraw;

app.setMode = (mode) => {
  if (mode === "live" && !app.liveNet) return;
  const changed = mode !== app.mode;
  app.mode = mode;
  document.body.classList.remove("mode-design", "mode-live", "mode-replay");
  document.body.classList.add(`mode-${mode}`);
  document.querySelectorAll("#modes .mode").forEach((b) => b.classList.toggle("active", b.dataset.mode === mode));
  if (mode !== "design") editor.setTool("select");
  if (changed) analysis.clear();
  redraw({ fit: changed });
  if (changed) app.selectTab(mode === "design" ? "inspect" : mode === "live" ? "run" : "timeline");
  if (mode === "replay" && !app.replay.data) app.loadRuns();
  if (mode === "live") liveView.renderPanels();
  editor.renderInspector();
  editor.renderTasks();
  analysis.render();
  const badge = document.getElementById("run-state");
  if (mode === "design") { badge.textContent = "design"; badge.className = "run-state"; document.getElementById("firings").textContent = ""; }
  // a replay before a run is picked: say what to do, and no badge left over from another mode
  const picking = mode === "replay" && !app.replay.data;
  if (picking) {
    badge.textContent = "replay"; badge.className = "run-state"; document.getElementById("firings").textContent = "";
    app.hint(REPLAY_HINT);
  } else if (document.getElementById("hint").textContent === REPLAY_HINT) app.hint("");
  runsView.render();
};
const REPLAY_HINT = "pick a run in the Runs panel on the right to replay it";

app.selectTab = (name) => {
  document.querySelectorAll("#tabs .tab").forEach((b) => b.classList.toggle("active", b.dataset.tab === name));
  document.querySelectorAll("#side .panel").forEach((p) => p.classList.toggle("active", p.id === `panel-${name}`));
  if (name === "timeline" && !app.replay.runs.length) app.loadRuns();
};
document.querySelectorAll("#tabs .tab").forEach((b) => b.addEventListener("click", () => app.selectTab(b.dataset.tab)));
document.querySelectorAll("#modes .mode").forEach((b) => b.addEventListener("click", () => app.setMode(b.dataset.mode)));

/** Change the current draft: fn(draft) edits it in place (return false to cancel). */
app.edit = (fn, { structural = true } = {}) => {
  const draft = app.currentDraft();
  if (!draft) return;
  if (structural && app.mode !== "design") { app.message("switch to Design to change the net"); return; }
  const before = clone(draft);
  if (fn(draft) === false) return;
  if (app.mode === "design") app.design.history.record(before);
  redraw();
  if (structural) { editor.renderInspector(); editor.renderTasks(); }
  if (app.mode === "design") validateSoon();
  updateButtons();
};

app.undo = () => {
  if (app.mode !== "design") return;
  const prev = app.design.history.undo(app.design.draft);
  if (!prev) { app.message("nothing to undo"); return; }
  app.design.draft = prev;
  afterReplace();
};
app.redo = () => {
  if (app.mode !== "design") return;
  const next = app.design.history.redo(app.design.draft);
  if (!next) { app.message("nothing to redo"); return; }
  app.design.draft = next;
  afterReplace();
};
function afterReplace() {
  app.graph.cy.elements().unselect();
  redraw();
  editor.renderInspector();
  editor.renderTasks();
  validateSoon();
  updateButtons();
}

// ------------------------------------------------------------------ the drawing keeps your work
/** Whether the design drawing differs from the file it was opened from or saved to. */
function isDirty() {
  const d = app.design;
  return !!d.draft && d.saved !== null && JSON.stringify(d.draft) !== d.saved;
}
function updateDirty() {
  app.design.dirty = isDirty();
  const shown = app.design.dirty;
  document.getElementById("dirty").hidden = !shown;
  document.title = `${shown ? "\u25CF " : ""}${app.design.draft?.net?.name || "petrobot"} \u2014 petrobot console`;
  document.body.dataset.dirty = shown ? "1" : "0";
}
function markSaved() { app.design.saved = JSON.stringify(app.design.draft); updateDirty(); }
app.markSaved = markSaved;

/** Ask before discarding unsaved changes; resolves true to go on. */
app.confirmDiscard = (what) => new Promise((resolve) => {
  updateDirty();
  if (!app.design.dirty) { resolve(true); return; }
  const d = document.getElementById("confirm-dialog");
  document.getElementById("confirm-title").textContent = `${what}: discard the changes?`;
  document.getElementById("confirm-text").textContent =
    `The drawing of ${app.design.path || "the new net"} has changes that are not saved. ${what} discards them; Save keeps them.`;
  let answered = false;
  const answer = (yes) => { if (answered) return; answered = true; d.close(); resolve(yes); };
  document.getElementById("confirm-yes").onclick = () => answer(true);
  document.getElementById("confirm-no").onclick = () => answer(false);
  d.onclose = () => answer(false);
  d.showModal();
});
window.addEventListener("beforeunload", (ev) => {
  if (isDirty()) { ev.preventDefault(); ev.returnValue = ""; }  // the browser asks before a reload or close
});

function updateButtons() {
  document.getElementById("undo").disabled = !app.design.history.canUndo;
  document.getElementById("redo").disabled = !app.design.history.canRedo;
  document.getElementById("save").disabled = !app.control;
  document.getElementById("save").title = app.control ? "save to the net file (Ctrl+S)" : "read-only: saving needs the console's token";
  document.getElementById("start-run").disabled = !app.control;
  document.getElementById("start-run").title = app.control
    ? "start a run of a net on the nodes of services.toml, or resume an interrupted one"
    : "read-only: starting runs needs the console's token";
  document.querySelector('#modes [data-mode="live"]').disabled = !app.liveNet;
  document.querySelector('#modes [data-mode="replay"]').disabled = !app.journal;
  updateDirty();
}
app.updateButtons = updateButtons;

// ------------------------------------------------------------------ validation (server side: one implementation)
let validateTimer = null;
let validating = false;
let again = false;
// each change asked to be checked is counted; the Problems panel shows the checks of change
// `checkedChange`, so that a slow check of an older drawing is never read as the current one's
let changes = 0;
let checkedChange = 0;
app.checkPending = () => checkedChange !== changes;
function checkedNow() { checkedChange = changes; }
function validateSoon(delay = 250) {
  changes += 1;
  clearTimeout(validateTimer);
  validateTimer = setTimeout(validate, delay);
}
async function validate() {
  const draft = app.currentDraft();
  if (!draft || !app.link.open) return;
  if (validating) { again = true; return; }
  validating = true;
  const asked = changes;
  // an edited drawing is no file yet: its problems say "unsaved drawing" and point to their elements
  const reply = await app.link.request("validate", { draft });
  validating = false;
  if (reply.ok) {
    app.validation = reply.validation;
    checkedChange = asked;
    renderProblems(app);
    editor.renderTasks();
    document.body.dataset.checked = String(Date.now());
  }
  if (again) { again = false; validate(); }
}
app.validate = validate;

app.focus = (problem) => {
  const cy = app.graph.cy;
  if (!problem.id) return;
  let target = cy.getElementById(problem.id);
  if (target.empty()) target = cy.getElementById("arc:" + problem.id);
  if (problem.kind === "task") { app.selectTab("tasks"); return; }
  if (target.nonempty()) {
    cy.elements().unselect();
    target.select();
    cy.animate({ center: { eles: target }, duration: 200 });
    app.selectTab("inspect");
  }
};

// ------------------------------------------------------------------ files
app.openNet = async (path, { confirm = true } = {}) => {
  if (confirm && !(await app.confirmDiscard(`Open ${path}`))) return;
  let net;
  try { net = await api(`/api/net?path=${encodeURIComponent(path)}`, token); }
  catch (e) { app.message(String(e.message || e), "bad"); return; }
  app.design = { draft: net.draft, path: net.path, history: new History(), dirty: false, saved: null };
  app.validation = net.validation;
  checkedNow();
  app.setMode("design");
  redraw({ fit: true });
  if (net.laid_out && app.graph.cy.nodes().length <= TIDY_MAX) {
    // no positions in the file: ELK's layout, labels kept clear (the file itself is unchanged); the
    // error-recovery branches hidden, as the paper suggests, one click away
    if (app.graph.cy.nodes(".hidden-branch").nonempty()) setShowHidden(false);
    const positions = await app.graph.tidy();
    for (const [id, xy] of Object.entries(positions)) { const node = findNode(app.design.draft, id); if (node) node.item.pos = xy; }
  }
  markSaved();
  renderProblems(app);
  editor.renderInspector();
  editor.renderTasks();
  updateButtons();
  app.message(`opened ${net.path}${net.laid_out ? " (no positions in the file: laid out automatically; Save keeps this drawing)" : ""}`);
  markReady();
};
const TIDY_MAX = 400;

function dialog(id) {
  const d = document.getElementById(id);
  d.querySelectorAll("[data-close]").forEach((b) => { b.onclick = () => d.close(); });
  d.showModal();
  return d;
}
app.dialog = dialog;

document.getElementById("open").addEventListener("click", async () => {
  const d = dialog("open-dialog");
  const list = document.getElementById("open-list");
  const input = document.getElementById("open-path");
  list.replaceChildren(el("li", { class: "small" }, "..."));
  let data = { opened: app.nets, files: [] };
  try { data = await api("/api/nets", token); } catch (e) { /* the opened nets still show */ }
  const files = [...new Set([...data.opened, ...data.files])];
  list.replaceChildren(...files.map((f) => {
    const li = el("li", {}, f);
    li.addEventListener("click", () => { input.value = f; list.querySelectorAll("li").forEach((x) => x.classList.toggle("sel", x === li)); });
    li.addEventListener("dblclick", () => { d.close(); app.openNet(f); });
    return li;
  }));
  if (!app.control) list.append(el("li", { class: "small" }, "read-only: only the nets the console was started with"));
  document.getElementById("open-go").onclick = () => { d.close(); if (input.value.trim()) app.openNet(input.value.trim()); };
});

app.save = async (path = null) => {
  if (!app.control) { app.message("read-only: saving needs the console's token", "bad"); return; }
  const draft = app.currentDraft();
  if (!draft) return;
  const current = app.mode === "design" ? app.design.path : app.mode === "live" ? app.liveNet?.path : null;
  if (!path) {
    const d = dialog("save-dialog");
    const input = document.getElementById("save-path");
    input.value = current && /\.(toml|pnml)$/.test(current) ? current : `${draft.net.name || "untitled"}.toml`;
    document.getElementById("save-note").textContent = app.validation && app.validation.problems.length
      ? `the net has ${app.validation.problems.length} problem(s): it is saved as drawn, in TOML` : "";
    document.getElementById("save-go").onclick = () => { d.close(); app.save(input.value.trim()); };
    input.focus();
    return;
  }
  const reply = await app.link.request("save", { path, draft });
  if (!reply.ok) { app.message(`not saved: ${reply.reason}`, "bad"); return; }
  if (app.mode === "design") { app.design.path = reply.path; markSaved(); }
  app.validation = reply.validation;
  if (app.mode === "design" && JSON.stringify(app.design.draft) === JSON.stringify(draft)) checkedNow();
  renderProblems(app);
  const n = reply.validation.problems.length;
  app.message(`saved ${reply.path}${n ? ` with ${n} problem${n === 1 ? "" : "s"}` : ": petrobot check finds no problem"}`, n ? "bad" : "ok");
  document.body.dataset.saved = reply.path;
};
document.getElementById("save").addEventListener("click", () => app.save());

document.getElementById("new").addEventListener("click", async () => {
  if (!(await app.confirmDiscard("New"))) return;
  app.design = { draft: emptyDraft(), path: null, history: new History(), dirty: false, saved: null };
  app.design.saved = JSON.stringify(app.design.draft);
  app.validation = null;
  app.setMode("design");
  renderProblems(app);
  validateSoon(0);
  updateButtons();
});

document.getElementById("export").addEventListener("click", () => {
  const d = dialog("export-dialog");
  for (const fmt of ["toml", "pnml", "dot", "png"]) {
    document.getElementById(`exp-${fmt}`).onclick = async () => {
      d.close();
      const draft = app.currentDraft();
      if (!draft) return;
      const name = draft.net.name || "net";
      if (fmt === "png") {
        try { download(await app.graph.png(), `${name}.png`); } catch (e) { app.message(`export: ${e.message || e}`, "bad"); }
        return;
      }
      try {
        const text = await api(`/api/export?format=${fmt}&hidden=${app.graph.showHidden ? 1 : 0}`, token,
                               { method: "POST", body: draft, text: true });
        download(URL.createObjectURL(new Blob([text], { type: "text/plain" })), `${name}.${fmt}`);
      } catch (e) { app.message(`export: ${e.message || e}`, "bad"); }
    };
  }
});

function download(href, name) {
  const a = el("a", { href, download: name });
  document.body.append(a);
  a.click();
  a.remove();
}

function setShowHidden(show) {
  app.graph.setShowHidden(show);
  document.getElementById("toggle-hidden").classList.toggle("on", !show);
}
document.getElementById("toggle-hidden").addEventListener("click", () => {
  setShowHidden(!app.graph.showHidden);
  app.message(app.graph.showHidden ? "error-recovery branches shown"
    : "error-recovery branches hidden: the \u2295 marks beside their places show them again in one click");
});
app.graph.onReveal = (place) => {
  document.getElementById("toggle-hidden").classList.toggle("on", false);
  app.message(`error-recovery branches shown (from ${place})`);
};
document.getElementById("labels").addEventListener("click", () => {
  app.graph.labelMode = nextLabelMode(app.graph.labelMode);
  redraw();
  app.message({ both: "transitions labelled with their names, then their events", names: "transitions labelled with their names",
                events: "transitions labelled with their events (as in the paper's Fig. 1)" }[app.graph.labelMode]);
});
document.getElementById("fit").addEventListener("click", () => app.graph.fit());
app.tidy = async () => {
  const n = app.graph.cy.nodes().length;
  if (n > TIDY_MAX) { app.message(`Tidy lays out nets of up to ${TIDY_MAX} elements; this one keeps its layout`, "bad"); return; }
  const positions = await app.graph.tidy();
  app.edit((d) => {
    for (const [id, xy] of Object.entries(positions)) { const node = findNode(d, id); if (node) node.item.pos = xy; }
  }, { structural: false });
  app.graph.fit();
  document.body.dataset.tidied = String(Date.now());
};
document.getElementById("tidy").addEventListener("click", () => app.tidy());

// what a node is, on hover: its id, label, kind, events (the drawing shows short labels)
const info = document.getElementById("info-pop");
let infoTimer = null;
app.graph.cy.on("mouseover", "node", (ev) => {
  clearTimeout(infoTimer);
  const target = ev.target;
  infoTimer = setTimeout(() => {
    const draft = app.currentDraft();
    const node = draft && findNode(draft, target.id());
    if (!node || !document.getElementById("task-pop").hidden || !document.getElementById("node-pop").hidden) return;
    const it = node.item;
    const lines = node.kind === "place"
      ? [`place ${it.id}`, it.label, `${it.kind || (it.task ? "primitive_task" : "plain")}${it.task ? ` of task ${it.task}` : ""}`]
      : [`transition ${it.id}`, it.label, (it.events || []).join(", ") || "no event: fires when enabled", it.hidden ? "error-recovery branch (hidden = true)" : ""];
    info.replaceChildren(...lines.filter(Boolean).map((t, i) => el(i ? "div" : "b", {}, t)));
    const rp = target.renderedPosition();
    info.style.left = `${rp.x + 28}px`;
    info.style.top = `${Math.max(4, rp.y + 18)}px`;
    info.hidden = false;
  }, 350);
});
app.graph.cy.on("mouseout", "node", () => { clearTimeout(infoTimer); info.hidden = true; });
app.graph.cy.on("viewport tapstart", () => { clearTimeout(infoTimer); info.hidden = true; });

function markReady() {
  requestAnimationFrame(() => requestAnimationFrame(() => {
    document.body.dataset.ready = "1";
    window.petrobotReadyAt = performance.now();
  }));
}

// ------------------------------------------------------------------ the connection
const editor = initEditor(app);
const liveView = initLive(app);
initReplay(app);
const analysis = initAnalysis(app);
app.redrawAnalysis = () => analysis.redraw();
const runsView = initRuns(app);

app.link = new Link(token, {
  onOpen() {
    const l = document.getElementById("link");
    l.textContent = "connected"; l.className = "link up";
  },
  onClose(reason, final) {
    const l = document.getElementById("link");
    // a run that has ended closes its console: the page keeps the final marking and the summary
    const ended = final && app.live?.ended;
    l.textContent = ended ? "run ended" : final ? "closed" : "reconnecting"; l.className = "link down";
    l.title = ended ? "the run has ended and its console has closed; this page keeps its final state" : "connection to the console server";
    app.message(ended ? `${reason}: the final marking and the summary (Run panel) stay on this page` : reason, final ? "" : "bad");
    document.body.dataset.closed = reason;
  },
  welcome(msg) {
    app.control = msg.control;
    app.nets = msg.nets;
    app.journal = msg.journal;
    app.servicesKnown = msg.services;
    app.definitions = msg.definitions || {};
    app.runs = msg.runs || [];
    const access = document.getElementById("access");
    access.textContent = msg.control ? "control" : "read-only";
    access.className = "access" + (msg.control ? " control" : "");
    access.title = msg.control ? "this page may steer runs and save files" : "opened without the console's token: the page follows but cannot steer or save";
    updateButtons();
    runsView.render();
    const wanted = app.wantRun && app.runs.some((r) => r.run === app.wantRun) ? app.wantRun : null;
    app.wantRun = null;
    if (wanted && msg.live?.run !== wanted) {
      app.watch(wanted);
    } else if (msg.live && msg.net) {
      startLive(msg.live, msg.net);
    } else if (!app.design.draft) {
      if (msg.nets.length) app.openNet(msg.nets[0], { confirm: false });
      else { app.design.draft = emptyDraft(); markSaved(); app.setMode("design"); validateSoon(0); markReady(); }
    }
    analysis.render();
  },
  run(msg) {
    if (msg.journal) app.journal = msg.journal;  // a run started from the page may have made the journal
    startLive(msg.live, msg.net);
  },
  runs(msg) { app.runs = msg.runs; runsView.render(); },
  frame(msg) { liveView.onFrame(msg); },
  snapshot(msg) { liveView.load(msg); },
  health(msg) { liveView.setHealth(msg); },
  bye(msg) { app.message(msg.reason); },
});

function startLive(snapshot, net) {
  app.liveNet = net;
  if (!app.design.draft) {
    app.design = { draft: clone(net.draft), path: net.path, history: new History(), dirty: false, saved: null };
    markSaved();
  }
  app.validation = net.validation;
  checkedNow();
  liveView.load(snapshot);
  updateButtons();
  const was = app.mode;
  app.setMode("live");
  if (was === "live") redraw({ fit: true });  // another run's net
  renderProblems(app);
  runsView.render();
  document.body.dataset.watching = snapshot.run || "";
  markReady();
}
app.startLive = startLive;

/** Follow another live run (its frames replace the current one's). */
app.watch = async (runId) => {
  const reply = await app.link.request("watch", { run: runId });
  if (!reply.ok) app.message(reply.reason, "bad");
};

app.setMode("design");
app.selectTab("inspect");
app.link.connect();
updateButtons();
