// Side panels that are neither the editor nor the run: problems (the checks of `petrobot check`) and analyses.

import { el } from "./ui.js";

export function renderProblems(app) {
  const panel = document.getElementById("panel-problems");
  const count = document.getElementById("problem-count");
  const v = app.validation;
  panel.replaceChildren();
  if (!v) { panel.append(el("p", { class: "empty" }, "not checked yet")); count.textContent = ""; return; }
  panel.append(el("h3", {}, "Checks"));
  panel.append(el("p", { class: "small" }, "the same rules and messages as petrobot check; the line numbers are those of the file Save writes"
    + (app.servicesKnown ? "; placement checked against services.toml" : "; placement not checked (no services.toml)")));
  count.textContent = String(v.problems.length);
  count.classList.toggle("zero", v.problems.length === 0);
  if (!v.problems.length) panel.append(el("div", { class: "okline" }, `OK ${v.summary}`));
  for (const p of v.problems) {
    const where = p.text.slice(0, p.text.length - p.problem.length).replace(/: $/, "");
    const box = el("div", { class: "problem", title: p.text }, el("div", {}, p.problem), el("div", { class: "where" }, where));
    box.addEventListener("click", () => app.focus(p));
    panel.append(box);
  }
  app.graph.setProblems(v.problems.filter((p) => p.id !== null && p.kind !== "task" && p.kind !== "net").map((p) => p.id));
}

export function initAnalysis(app) {
  const panel = document.getElementById("panel-analysis");
  const kinds = [["analyze", "qualitative: boundedness, liveness, reversibility, invariants"],
                 ["gspn", "quantitative: the GSPN view's measures, with the journal's measured times and reliabilities when the console has one open"],
                 ["perf", "J = 1 \u2212 R + \u03c1C of each action and task, from the journal"],
                 ["learn", "the learning automata, replayed from the journal, with their plot"]];
  const out = el("div");
  function render() {
    panel.replaceChildren(el("h3", {}, "Analyses of the open net"),
      el("p", { class: "small" }, "each runs the petrobot command of the same name on the net as drawn, in its own process"));
    for (const [kind, what] of kinds) {
      const b = el("button", { title: what }, `petrobot ${kind}`);
      b.disabled = !app.control;
      b.addEventListener("click", () => run(kind));
      panel.append(el("p", {}, b, " ", el("span", { class: "small" }, what)));
    }
    if (!app.control) panel.append(el("p", { class: "small" }, "read-only: analyses need the console's token"));
    panel.append(out);
  }
  async function run(kind) {
    const draft = app.currentDraft();
    if (!draft) return;
    out.replaceChildren(el("p", { class: "small" }, `running petrobot ${kind}...`));
    const run = app.mode === "replay" && app.replay?.data ? app.replay.data.run.id : null;
    const reply = await app.link.request("analyze", { kind, draft, run });
    out.replaceChildren();
    if (!reply.ok) { out.append(el("p", { class: "node-bad" }, reply.reason)); return; }
    const r = reply.report;
    out.append(el("h4", {}, `${r.command} \u2014 exit ${r.exit === null ? "killed" : r.exit}`));
    if (r.stdout) out.append(el("pre", { class: "report" }, r.stdout));
    if (r.stderr) out.append(el("pre", { class: "report node-bad" }, r.stderr));
    if (r.plot) out.append(el("img", { class: "plot", alt: `${kind} plot`, src: `data:image/png;base64,${r.plot}` }));
  }
  return { render };
}
