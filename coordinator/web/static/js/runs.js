// Runs started and followed from the page: the list of the runs the console follows (several nets at
// once, one per button in the header; a click follows another, `?run=ID` opens a page on one), and
// the dialog that starts a net file on the nodes of services.toml (the same preflight as
// `petrobot run`) or resumes an interrupted run of the journal.

import { api } from "./ws.js";
import { el, seconds } from "./ui.js";

const END_STATES = new Set(["completed", "stuck", "waiting_for_operator", "aborted", "deadline", "interrupted"]);

export function initRuns(app) {
  const strip = document.getElementById("live-runs");

  function render() {
    strip.replaceChildren();
    const watching = app.mode === "live" ? app.live?.runId : null;
    for (const r of app.runs || []) {
      const st = END_STATES.has(r.state) ? (r.state === "completed" ? "ended" : "error") : r.paused ? "paused" : r.state;
      const b = el("button", { class: r.run === watching ? "watching" : "", "data-run": r.run,
                               title: `${r.net} (run ${r.run}, ${r.origin === "page" ? "started from the page" : "petrobot run --console"}): `
                                      + `${r.state}${r.reason ? " \u2014 " + r.reason : ""}; open another window with ?run=${r.run} to watch it beside this one` },
        el("i", { class: `st ${st}` }), `${r.net} \u00b7 ${r.paused && !END_STATES.has(r.state) ? "paused" : r.state} \u00b7 ${r.firings}`);
      b.addEventListener("click", () => { if (r.run === watching) return; app.watch(r.run); });
      strip.append(b);
    }
  }

  // ------------------------------------------------------------------ starting a run
  const dlg = document.getElementById("run-dialog");
  const netSel = document.getElementById("run-net");
  const markingBox = document.getElementById("run-marking");

  async function controlPlaces(path) {
    try {
      const net = await api(`/api/net?path=${encodeURIComponent(path)}`, app.token);
      return net.draft.places.filter((p) => p.kind === "control");
    } catch (e) { return []; }
  }

  // the net chosen may change while its control places are fetched (the dialog shows the first net's
  // as it opens): only the latest choice's are shown, never two nets' fields at once
  let markingShown = 0;
  async function showMarking() {
    const mine = ++markingShown;
    markingBox.replaceChildren();
    const places = await controlPlaces(netSel.value);
    if (mine !== markingShown) return;
    markingBox.replaceChildren();
    if (!places.length) { markingBox.append(el("span", { class: "small" }, "no control place")); return; }
    for (const p of places) {
      const input = el("input", { type: "number", min: "0", value: String(p.tokens || 0), "data-place": p.id });
      markingBox.append(el("label", { for: "" }, `${p.id}${p.label ? ` (${p.label})` : ""}`), input);
    }
  }

  async function open() {
    if (!app.control) { app.message("read-only: starting runs needs the console's token", "bad"); return; }
    app.dialog("run-dialog");
    netSel.replaceChildren(el("option", {}, "..."));
    let files = [];
    try { const data = await api("/api/nets", app.token); files = [...new Set([...data.opened, ...data.files])]; } catch (e) { /* none */ }
    const current = app.design.path;
    netSel.replaceChildren(...files.map((f) => el("option", { value: f }, f)));
    if (current && files.includes(current)) netSel.value = current;
    await showMarking();
    const list = document.getElementById("run-resumable");
    list.replaceChildren(el("li", { class: "small" }, "reading the journal..."));
    let runs = [];
    try { runs = (await api("/api/runs", app.token)).runs || []; } catch (e) { /* no journal yet */ }
    const resumable = runs.filter((r) => (r.state === null || r.state === "interrupted") && !(app.runs || []).some((x) => x.run === r.id));
    list.replaceChildren(...resumable.map((r) => {
      const file = files.find((f) => f.replace(/^.*\//, "").replace(/\.(toml|pnml|xml)$/, "") === r.net);
      const li = el("li", { title: file ? `resume the last unfinished run of ${file}` : "no net file of this name under the console's folder" },
        `${r.id} ${r.net} \u00b7 ${r.state || "unfinished"} \u00b7 ${r.firings} firings \u00b7 ${seconds(r.duration_s)}`);
      li.addEventListener("click", () => { if (file) { dlg.close(); start("resume", { net: file }); } });
      return li;
    }));
    if (!resumable.length) list.replaceChildren(el("li", { class: "small" }, "none"));
  }
  netSel.addEventListener("change", showMarking);
  document.getElementById("start-run").addEventListener("click", open);
  document.getElementById("run-go").addEventListener("click", () => {
    const marking = {};
    for (const input of markingBox.querySelectorAll("input[data-place]")) marking[input.dataset.place] = Math.max(0, Math.trunc(Number(input.value) || 0));
    const deadline = document.getElementById("run-deadline").value;
    dlg.close();
    start("start", { net: netSel.value, marking, seed: Math.max(0, Math.trunc(Number(document.getElementById("run-seed").value) || 0)),
                     max_seconds: deadline ? Number(deadline) : null, degraded: document.getElementById("run-degraded").checked });
  });

  async function start(kind, fields) {
    app.message(`${kind === "start" ? "starting" : "resuming"} ${fields.net}: preflight of its actions on their nodes...`);
    const reply = await app.link.request(kind, fields);
    if (!reply.ok) { app.message(`${fields.net} did not ${kind}: ${reply.reason}`, "bad"); document.body.dataset.refused = reply.reason; return; }
    app.message(`${fields.net}: run ${reply.run} ${kind === "start" ? "started" : "resumed"}`, "ok");
  }
  app.startRun = start;

  return { render };
}
