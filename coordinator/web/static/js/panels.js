// The Problems panel: the checks of `petrobot check`, at the lines of the real file while the drawing is
// the file as it stands, said to be in the "unsaved drawing" once it is edited (click one: its element).

import { el } from "./ui.js";

export function renderProblems(app) {
  const panel = document.getElementById("panel-problems");
  const count = document.getElementById("problem-count");
  const v = app.validation;
  panel.replaceChildren();
  if (!v) { panel.append(el("p", { class: "empty" }, "not checked yet")); count.textContent = ""; return; }
  panel.append(el("h3", {}, "Checks"));
  panel.append(el("p", { class: "small" }, "the same rules and messages as petrobot check: at the lines of the file while the drawing is "
    + "that file as it stands, in the \u201cunsaved drawing\u201d once it is edited (click a problem to see its element)"
    + (app.servicesKnown ? "; placement checked against services.toml" : "; placement not checked (no services.toml)")));
  if (app.checkPending && app.checkPending()) panel.append(el("p", { class: "small" }, "checking the latest change\u2026"));
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
