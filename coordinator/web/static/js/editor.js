// Design: drawing the net with the mouse (paper section 5): tools, the element inspector, the tasks editor.
// Every change goes through app.edit(fn), which records undo, redraws and asks the server to validate.

import { addArc, arcKey, arcKind, deleteElements, findArc, findNode, freshId, NAME_RE, parseEvent, renameNode } from "./net.js";
import { el, field } from "./ui.js";

const KINDS = ["plain", "resource", "primitive_task", "control"];
const SCHEMES = ["", "pursuit", "lri", "fixed"];

export function initEditor(app) {
  const cy = app.graph.cy;
  let tool = "select";
  let arcSource = null;

  const ARC_TOOLS = { arc: "normal", inhibitor: "inhibitor", reset: "reset" };
  const ARC_HINTS = { arc: "drag from the source of the arc to its target (or click one, then the other)",
                      inhibitor: "drag from a place to the transition it inhibits (or click one, then the other)",
                      reset: "drag from a place to the transition that empties it (or click one, then the other)" };

  function setTool(name) {
    tool = name;
    document.querySelectorAll("#tools .tool").forEach((b) => b.classList.toggle("active", b.dataset.tool === name));
    document.body.className = document.body.className.replace(/\btool-\S+/g, "").trim() + ` tool-${name}`;
    clearArcSource();
    // with an arc tool a drag draws an arc: nodes are not moved
    cy.autoungrabify(name in ARC_TOOLS);
    const hints = { place: "click on the canvas to add a place", transition: "click on the canvas to add a transition",
                    ...ARC_HINTS, select: "" };
    app.hint(hints[name] || "");
  }
  function clearArcSource() { if (arcSource) cy.getElementById(arcSource).removeClass("arc-source"); arcSource = null; }
  app.setTool = setTool;

  document.querySelectorAll("#tools .tool").forEach((b) => b.addEventListener("click", () => setTool(b.dataset.tool)));

  cy.on("tap", (ev) => {
    if (app.mode !== "design") return;
    if (ev.target === cy) {
      if (tool === "place" || tool === "transition") {
        const at = [Math.round(ev.position.x), Math.round(ev.position.y)];
        let created = null;
        app.edit((d) => {
          if (tool === "place") { created = freshId(d, "p"); d.places.push({ id: created, pos: at }); }
          else { created = freshId(d, "t"); d.transitions.push({ id: created, pos: at }); }
        });
        cy.elements().unselect();
        cy.getElementById(created).select();
        app.selectTab("inspect");
      } else {
        clearArcSource();
      }
      return;
    }
    const target = ev.target;
    if (tool in ARC_TOOLS && target.isNode()) {
      if (dragged) { dragged = false; return; }  // that tap ended a drag that drew the arc already
      if (!arcSource) {
        if (tool !== "arc" && target.data("kind") !== "place") { app.message(`a${tool === "inhibitor" ? "n inhibitor" : " reset"} arc starts at a place`, "bad"); return; }
        arcSource = target.id();
        target.addClass("arc-source");
        app.hint(`now click the ${target.data("kind") === "place" ? "transition" : "place"} the arc goes to`);
        return;
      }
      const from = arcSource;
      clearArcSource();
      drawArc(from, target.id());
    }
  });

  function drawArc(from, to) {
    let error = null;
    app.edit((d) => { error = addArc(d, from, to, ARC_TOOLS[tool]); return error === null; });
    if (error) app.message(error, "bad");
    else app.message(`${ARC_TOOLS[tool] === "normal" ? "arc" : ARC_TOOLS[tool] + " arc"} ${from} \u2192 ${to}`);
    app.hint(ARC_HINTS[tool] || "");
  }

  // the Arc tools' drag: from a node to another draws an arc, a rubber band follows the pointer
  const rubber = document.getElementById("rubber");
  const band = rubber.querySelector("line");
  let dragFrom = null, dragged = false;
  cy.on("tapstart", "node", (ev) => {
    if (app.mode !== "design" || !(tool in ARC_TOOLS)) return;
    dragFrom = ev.target.id();
    dragged = false;
  });
  cy.on("tapdrag", (ev) => {
    if (dragFrom === null) return;
    const a = cy.getElementById(dragFrom).renderedPosition();
    const b = ev.renderedPosition;
    if (!b || (!dragged && Math.hypot(b.x - a.x, b.y - a.y) < 8)) return;
    dragged = true;
    band.setAttribute("x1", a.x); band.setAttribute("y1", a.y); band.setAttribute("x2", b.x); band.setAttribute("y2", b.y);
    rubber.removeAttribute("hidden");  // an SVG element has no hidden property
  });
  cy.on("tapend", (ev) => {
    const from = dragFrom;
    dragFrom = null;
    rubber.setAttribute("hidden", "");
    if (from === null || !dragged) { dragged = false; return; }
    const at = ev.renderedPosition || ev.position;
    const over = cy.nodes().filter((n) => {
      if (n.id() === from || n.style("display") === "none") return false;
      const bb = n.renderedBoundingBox({ includeLabels: false });
      return at && at.x >= bb.x1 - 4 && at.x <= bb.x2 + 4 && at.y >= bb.y1 - 4 && at.y <= bb.y2 + 4;
    });
    clearArcSource();
    if (over.empty()) { dragged = false; app.message("drop the arc on a place or a transition"); return; }
    drawArc(from, over[0].id());
    setTimeout(() => { dragged = false; }, 0);
  });

  // moving nodes: positions are part of the file (any mode; not structural)
  cy.on("dragfree", "node", (ev) => {
    const moved = cy.nodes(":selected").union(ev.target).not(".badge");
    const draft = app.currentDraft();
    if (!draft) return;
    app.edit((d) => {
      moved.forEach((n) => {
        const node = findNode(d, n.id());
        if (node) { const p = n.position(); node.item.pos = [Math.round(p.x * 10) / 10, Math.round(p.y * 10) / 10]; }
      });
    }, { structural: false });
  });
  cy.on("drag", "node.place", () => app.graph.refreshBadges());

  cy.on("select unselect", () => { if (app.mode !== "replay") renderInspector(); });

  function deleteSelection() {
    if (app.mode !== "design") return;
    const sel = cy.elements(":selected").not(".badge");
    if (sel.empty()) { app.message("select what to delete first"); return; }
    const nodes = sel.nodes().map((n) => n.id());
    const arcs = sel.edges().map((e) => e.data("key"));
    app.edit((d) => deleteElements(d, nodes, arcs));
    renderInspector();
  }
  document.getElementById("delete").addEventListener("click", deleteSelection);
  document.getElementById("undo").addEventListener("click", () => app.undo());
  document.getElementById("redo").addEventListener("click", () => app.redo());

  document.addEventListener("keydown", (ev) => {
    const typing = ["INPUT", "TEXTAREA", "SELECT"].includes(document.activeElement?.tagName);
    if ((ev.ctrlKey || ev.metaKey) && ev.key.toLowerCase() === "s") { ev.preventDefault(); app.save(); return; }
    if (typing) return;
    if ((ev.ctrlKey || ev.metaKey) && ev.key.toLowerCase() === "z") { ev.preventDefault(); ev.shiftKey ? app.redo() : app.undo(); return; }
    if ((ev.ctrlKey || ev.metaKey) && ev.key.toLowerCase() === "y") { ev.preventDefault(); app.redo(); return; }
    if (ev.ctrlKey || ev.metaKey || ev.altKey) return;
    if (ev.key === "Delete" || ev.key === "Backspace") { deleteSelection(); ev.preventDefault(); return; }
    if (ev.key === "Escape") { clearArcSource(); setTool("select"); return; }
    const keys = { v: "select", p: "place", t: "transition", a: "arc", i: "inhibitor", r: "reset" };
    if (app.mode === "design" && keys[ev.key]) setTool(keys[ev.key]);
    if (ev.key === "f") app.graph.fit();
  });

  // ------------------------------------------------------------------ the inspector
  const panel = document.getElementById("panel-inspect");

  function renderInspector() {
    const draft = app.currentDraft();
    const sel = cy.elements(":selected").not(".badge");
    panel.replaceChildren();
    if (!draft) { panel.append(el("p", { class: "empty" }, "no net open")); return; }
    if (sel.length !== 1) { renderNetForm(draft); return; }
    const item = sel[0];
    if (item.isEdge()) renderArcForm(draft, item.data("key"));
    else if (item.data("kind") === "place") renderPlaceForm(draft, item.id());
    else renderTransitionForm(draft, item.id());
  }
  app.renderInspector = renderInspector;

  const readOnly = () => app.mode !== "design";

  function renderNetForm(draft) {
    panel.append(el("h3", {}, "Net"));
    panel.append(field("name", input(draft.net.name ?? "", (v) => app.edit((d) => { d.net.name = v; }))));
    panel.append(field("description", textarea(draft.net.description ?? "", (v) => app.edit((d) => {
      if (v) d.net.description = v; else delete d.net.description; }))));
    const home = Object.entries(draft.net.home || {}).map(([p, n]) => `${p}=${n}`).join(", ");
    panel.append(field("home", input(home, (v) => app.edit((d) => {
      const out = {};
      for (const part of v.split(",").map((s) => s.trim()).filter(Boolean)) {
        const [p, n] = part.split("=").map((s) => s.trim());
        out[p] = Number.isInteger(Number(n)) ? Number(n) : n;
      }
      if (Object.keys(out).length) d.net.home = out; else delete d.net.home;
    }), "place=N, ... (the home marking)")));
    const topics = [...new Set(draft.transitions.flatMap((t) => (t.events || []).filter((e) => e.startsWith("ext:"))))];
    if (topics.length) {
      const inject = new Set(draft.operator?.inject || []);
      const boxes = topics.map((e) => {
        const box = el("input", { type: "checkbox" });
        box.checked = inject.has(e);
        box.disabled = readOnly();
        box.addEventListener("change", () => app.edit((d) => setRights(d, "inject", e, box.checked)));
        return el("label", { class: "chip" }, box, " ", e);
      });
      panel.append(field("operator may raise", el("div", { class: "chips" }, ...boxes)));
      panel.append(el("p", { class: "small" }, "[operator] inject: external events the operator may raise from the console (drills); the outcomes they may force are set per task in the Tasks tab"));
    }
    const counts = `${draft.places.length} places, ${draft.transitions.length} transitions, ${draft.arcs.length} arcs, ` +
      `${Object.keys(draft.tasks).length} primitive tasks`;
    panel.append(el("p", { class: "small" }, counts));
    panel.append(el("p", { class: "small" }, app.mode === "design"
      ? "Select an element to edit it. Tools: V select, P place, T transition, A arc, I inhibitor arc, R reset arc (drag from one element to the other); Delete removes; Ctrl+Z / Ctrl+Y undo and redo."
      : app.mode === "live" ? "Following the run. Click a control place to insert or remove tokens; use the bar below to pause, step, resume or abort."
      : "Replaying a run of the journal: move along the timeline below."));
  }

  function renderPlaceForm(draft, id) {
    const node = findNode(draft, id);
    if (!node) return;
    const p = node.item;
    panel.append(el("h3", {}, `Place ${id}`));
    panel.append(field("id", input(p.id, (v) => rename(id, v))));
    panel.append(field("label", input(p.label ?? "", (v) => app.edit((d) => set(findNode(d, id).item, "label", v)))));
    const kind = p.kind || (p.task ? "primitive_task" : "plain");
    panel.append(field("kind", select(KINDS, kind, (v) => app.edit((d) => {
      const it = findNode(d, id).item;
      if (v === "plain") delete it.kind; else it.kind = v;
      if (v === "primitive_task") {
        if (!it.task) it.task = Object.keys(d.tasks)[0] || newTask(d, id);
      } else delete it.task;
    }))));
    if (kind === "primitive_task") {
      const names = Object.keys(draft.tasks);
      const options = [...names, "(new task)"];
      panel.append(field("task", select(options, p.task || "", (v) => app.edit((d) => {
        const it = findNode(d, id).item;
        it.task = v === "(new task)" ? newTask(d, id) : v;
      }))));
      if (p.task) panel.append(el("p", { class: "small" }, "edit the task's actions in the Tasks tab"));
    }
    panel.append(field("tokens", number(p.tokens ?? 0, 0, (v) => app.edit((d) => set(findNode(d, id).item, "tokens", v, 0)))));
    panel.append(field("capacity", number(p.capacity ?? "", 0, (v) => app.edit((d) => set(findNode(d, id).item, "capacity", v)))));
    const arcs = draft.arcs.filter((a) => a.from === id || a.to === id).length;
    panel.append(el("p", { class: "small" }, `${arcs} arc${arcs === 1 ? "" : "s"}`));
    if (app.mode === "live" && kind === "control") panel.append(el("p", { class: "small" }, "click the place on the drawing to insert or remove tokens"));
  }

  function renderTransitionForm(draft, id) {
    const node = findNode(draft, id);
    if (!node) return;
    const t = node.item;
    panel.append(el("h3", {}, `Transition ${id}`));
    panel.append(field("id", input(t.id, (v) => rename(id, v))));
    panel.append(field("label", input(t.label ?? "", (v) => app.edit((d) => set(findNode(d, id).item, "label", v)))));
    // events
    const chips = el("div", { class: "chips" });
    for (const e of t.events || []) {
      const x = el("button", { title: "unlink this event", disabled: readOnly() ? "" : null }, "\u00d7");
      x.addEventListener("click", () => app.edit((d) => {
        const it = findNode(d, id).item;
        it.events = (it.events || []).filter((y) => y !== e);
        if (!it.events.length) delete it.events;
      }));
      chips.append(el("span", { class: "chip" }, e, x));
    }
    if (!(t.events || []).length) chips.append(el("span", { class: "small" }, "none: fires as soon as it is enabled"));
    panel.append(field("events", chips));
    if (!readOnly()) panel.append(field("link event", eventAdder(draft, id)));
    panel.append(field("priority", number(t.priority ?? 0, null, (v) => app.edit((d) => set(findNode(d, id).item, "priority", v, 0)))));
    panel.append(field("weight", expression(t.weight ?? 1, "a number > 0 or a marking expression, e.g. 1 + #queue",
      (v) => app.edit((d) => set(findNode(d, id).item, "weight", v, 1)))));
    panel.append(field("timing", select(["immediate", "exponential"], t.kind || "immediate", (v) => app.edit((d) => {
      const it = findNode(d, id).item;
      if (v === "immediate") { delete it.kind; delete it.rate; delete it.servers; } else { it.kind = v; if (!it.rate) it.rate = 1.0; }
    }))));
    if (t.kind === "exponential") {
      panel.append(field("rate (1/s)", expression(t.rate ?? 1, "a number > 0 (1/s per server) or a marking expression, e.g. min(#q, 3) * 2",
        (v) => app.edit((d) => set(findNode(d, id).item, "rate", v)))));
      const servers = t.servers ?? 1;
      panel.append(field("servers", input(String(servers), (v) => app.edit((d) => {
        const text = v.trim();
        set(findNode(d, id).item, "servers", text === "infinite" ? "infinite" : text === "" ? null : Number.isInteger(Number(text)) ? Number(text) : text, 1);
      }), "1, 2, ... or infinite")));
    }
    panel.append(el("p", { class: "small" }, "rates and weights: a number, or a marking expression (#place, + - * /, min, max) checked like petrobot check (docs/netfile.md)"));
    const hidden = el("input", { type: "checkbox" });
    hidden.checked = t.hidden === true;
    hidden.disabled = readOnly();
    hidden.addEventListener("change", () => app.edit((d) => set(findNode(d, id).item, "hidden", hidden.checked ? true : null)));
    panel.append(field("error branch", el("label", {}, hidden, " hidden (an error-recovery branch displays may hide)")));
    const ins = draft.arcs.filter((a) => a.to === id), outs = draft.arcs.filter((a) => a.from === id);
    panel.append(el("p", { class: "small" }, `inputs: ${ins.map((a) => a.from + (a.inhibitor ? " (inhibitor)" : "")).join(", ") || "none"}; ` +
      `outputs: ${outs.map((a) => a.to).join(", ") || "none"}`));
  }

  function renderArcForm(draft, key) {
    const arc = findArc(draft, key);
    if (!arc) return;
    const kind = arcKind(arc);
    panel.append(el("h3", {}, `Arc ${arc.from} \u2192 ${arc.to}`));
    const fromPlace = findNode(draft, arc.from)?.kind === "place";
    const kinds = fromPlace ? ["normal", "inhibitor", "reset"] : ["normal"];
    panel.append(field("kind", select(kinds, kind, (v) => {
      let moved = null;
      app.edit((d) => {
        const a = findArc(d, key); if (!a) return false;
        delete a.inhibitor; delete a.reset;
        if (v === "inhibitor") a.inhibitor = true;
        if (v === "reset") { a.reset = true; delete a.weight; } else if (a.weight === undefined) a.weight = 1;
        if (d.arcs.filter((x) => arcKey(x) === arcKey(a)).length > 1) { app.message(`there is such an arc ${a.from} -> ${a.to} already`, "bad"); return false; }
        moved = arcKey(a);
      });
      cy.elements().unselect();
      if (moved) cy.getElementById("arc:" + moved).select();
    })));
    if (kind !== "reset") {
      panel.append(field(kind === "inhibitor" ? "threshold" : "weight", number(arc.weight ?? 1, 1, (v) => app.edit((d) => {
        const a = findArc(d, key); if (a) a.weight = v ?? 1; }))));
    }
    panel.append(el("p", { class: "small" }, { normal: "consumes (input) or produces (output) weight tokens",
      inhibitor: "disables the transition while the place holds \u2265 threshold tokens",
      reset: "firing the transition empties the place, whatever it holds (no weight; docs/netfile.md, Reset arcs)" }[kind]));
  }

  function eventAdder(draft, id) {
    const kind = select(["int", "ext"], "int", () => update());
    const taskSel = el("select");
    const inputsTasks = draft.arcs.filter((a) => a.to === id && !a.inhibitor)
      .map((a) => findNode(draft, a.from)?.item).filter((p) => p && p.task).map((p) => p.task);
    for (const t of [...new Set([...inputsTasks, ...Object.keys(draft.tasks)])]) taskSel.append(el("option", { value: t }, t));
    const outcome = el("input", { type: "text", value: "ok", size: 8, title: "ok, error, success, failure or a named outcome" });
    const topic = el("input", { type: "text", placeholder: "topic", size: 14 });
    const add = el("button", {}, "link");
    const box = el("div", { class: "chips event-adder" }, kind, taskSel, el("span", {}, "."), outcome, topic, add);
    function update() {
      const isInt = kind.value === "int";
      taskSel.hidden = !isInt; outcome.hidden = !isInt; box.children[2].hidden = !isInt; topic.hidden = isInt;
    }
    update();
    add.addEventListener("click", () => {
      const ev = kind.value === "int" ? `int:${taskSel.value}.${outcome.value.trim()}` : `ext:${topic.value.trim()}`;
      if (!parseEvent(ev)) { app.message(`bad event name ${ev}: use int:<task>.<outcome> or ext:<topic>`, "bad"); return; }
      app.edit((d) => {
        const it = findNode(d, id).item;
        it.events = [...new Set([...(it.events || []), ev])];
      });
    });
    return box;
  }

  function rename(oldId, newId) {
    let error = null;
    app.edit((d) => { error = renameNode(d, oldId, newId.trim()); return error === null; });
    if (error) { app.message(error, "bad"); renderInspector(); return; }
    cy.elements().unselect();
    cy.getElementById(newId.trim()).select();
  }

  function newTask(d, placeId) {
    let base = placeId.replace(/[^A-Za-z0-9_]/g, "_").replace(/^([^A-Za-z_])/, "_$1");
    if (!NAME_RE.test(base)) base = "task";
    let name = base, i = 2;
    while (name in d.tasks) name = `${base}${i++}`;
    d.tasks[name] = { actions: ["echo"] };
    return name;
  }

  // ------------------------------------------------------------------ form widgets bound to edits
  function input(value, onChange, placeholder = "") {
    const x = el("input", { type: "text", value: String(value), placeholder });
    x.disabled = readOnly();
    x.addEventListener("change", () => onChange(x.value));
    return x;
  }
  function textarea(value, onChange) {
    const x = el("textarea", { rows: 3 });
    x.value = value;
    x.disabled = readOnly();
    x.addEventListener("change", () => onChange(x.value));
    return x;
  }
  /** A number or a marking expression (a string the server parses, as petrobot check does). */
  function expression(value, placeholder, onChange) {
    return input(String(value), (v) => {
      const text = v.trim();
      if (text === "") { onChange(null); return; }
      const n = Number(text);
      onChange(Number.isFinite(n) && /^[-+0-9.eE]+$/.test(text) ? n : text);
    }, placeholder);
  }
  function number(value, min, onChange, step = "1") {
    const x = el("input", { type: "number", value: String(value), step });
    if (min !== null) x.min = String(min);
    x.disabled = readOnly();
    x.addEventListener("change", () => {
      if (x.value === "") { onChange(null); return; }
      const v = Number(x.value);
      onChange(step === "1" ? Math.trunc(v) : v);
    });
    return x;
  }
  function select(options, value, onChange) {
    const x = el("select");
    for (const o of options) x.append(el("option", { value: o }, o || "(none)"));
    x.value = value;
    x.disabled = readOnly();
    x.addEventListener("change", () => onChange(x.value));
    return x;
  }
  function set(item, key, value, dflt = undefined) {
    if (value === null || value === "" || value === undefined || value === dflt) delete item[key];
    else item[key] = value;
  }

  // ------------------------------------------------------------------ the tasks editor
  const tasksPanel = document.getElementById("panel-tasks");
  function renderTasks() {
    const draft = app.currentDraft();
    tasksPanel.replaceChildren();
    if (!draft) return;
    const placement = app.validation?.placement || {};
    const hasPlacement = app.servicesKnown;
    tasksPanel.append(el("h3", {}, "Primitive tasks"));
    if (!hasPlacement) tasksPanel.append(el("p", { class: "small" }, "no services.toml: placement is not checked"));
    for (const [name, task] of Object.entries(draft.tasks)) {
      const box = el("div", { class: "task-box" });
      box.append(el("h4", {}, name, " ", el("span", { class: "small" },
        `places: ${draft.places.filter((p) => p.task === name).map((p) => p.id).join(", ") || "none"}`)));
      const table = el("table", { class: "grid" });
      table.append(el("tr", {}, el("th", {}, "action"), el("th", {}, "node"), el("th", {}, "cost"), el("th", {}, "params"), el("th", {}, "")));
      const actions = Array.isArray(task.actions) ? task.actions : [];
      actions.forEach((a, i) => {
        const spec = typeof a === "string" ? { name: a } : a;
        const node = placement[spec.name];
        const nodeCell = !hasPlacement ? el("td", { class: "small" }, "?") : node ? el("td", { class: "node-ok" }, node)
          : el("td", { class: "unplaced", title: "not placed on any node in services.toml" }, "not placed");
        const nameIn = el("input", { type: "text", value: spec.name || "", size: 14 });
        nameIn.disabled = readOnly();
        nameIn.addEventListener("change", () => editAction(name, i, { name: nameIn.value.trim() }));
        const costIn = el("input", { type: "number", value: spec.cost ?? "", step: "any", min: "0", style: { width: "5em" } });
        costIn.disabled = readOnly();
        costIn.addEventListener("change", () => editAction(name, i, { cost: costIn.value === "" ? null : Number(costIn.value) }));
        const paramsIn = el("input", { type: "text", value: spec.params ? JSON.stringify(spec.params) : "", size: 12,
                                       placeholder: '{"key": value}', title: "parameters as JSON" });
        paramsIn.disabled = readOnly();
        paramsIn.addEventListener("change", () => {
          if (!paramsIn.value.trim()) { editAction(name, i, { params: null }); return; }
          try { editAction(name, i, { params: JSON.parse(paramsIn.value) }); }
          catch (e) { app.message(`params of ${spec.name}: not JSON (${e.message})`, "bad"); }
        });
        const del = el("button", { title: "remove this alternative" }, "\u00d7");
        del.disabled = readOnly();
        del.addEventListener("click", () => app.edit((d) => { d.tasks[name].actions.splice(i, 1); }));
        table.append(el("tr", {}, el("td", {}, nameIn), nodeCell, el("td", {}, costIn), el("td", {}, paramsIn), el("td", {}, del)));
      });
      box.append(table);
      if (!readOnly()) {
        const add = el("button", {}, "+ alternative action");
        add.addEventListener("click", () => app.edit((d) => { d.tasks[name].actions = [...(d.tasks[name].actions || []), "echo"]; }));
        box.append(add);
      }
      const num = (key, label, step = "any") => field(label, number(task[key] ?? "", 0, (v) => app.edit((d) => set(d.tasks[name], key, v)), step));
      box.append(num("deadline_s", "deadline (s)"));
      box.append(num("mean_time_s", "mean time (s)"));
      box.append(num("reliability", "reliability"));
      const learner = task.learner || {};
      box.append(field("learner", select(SCHEMES, learner.scheme || "", (v) => app.edit((d) => {
        if (!v) delete d.tasks[name].learner; else d.tasks[name].learner = { ...(d.tasks[name].learner || {}), scheme: v };
      }))));
      if (learner.scheme && learner.scheme !== "fixed") {
        box.append(field("learning rate", number(learner.rate ?? "", 0, (v) => app.edit((d) => {
          const l = { ...(d.tasks[name].learner || {}) }; if (v === null) delete l.rate; else l.rate = v; d.tasks[name].learner = l;
        }), "any")));
      }
      const force = new Set(draft.operator?.force?.[name] || []);
      const named = [...new Set(draft.transitions.flatMap((t) => (t.events || [])
        .map((e) => parseEvent(e)).filter((e) => e && e.kind === "int" && e.task === name && !["ok", "error", "success", "failure"].includes(e.outcome))
        .map((e) => `failure.${e.outcome}`)))];
      const outcomes = [...new Set(["success", "failure", "error", ...named, ...force])];
      box.append(field("operator may force", el("div", { class: "chips" }, ...outcomes.map((o) => {
        const cb = el("input", { type: "checkbox" });
        cb.checked = force.has(o);
        cb.disabled = readOnly();
        cb.addEventListener("change", () => app.edit((d) => setRights(d, "force", o, cb.checked, name)));
        return el("label", { class: "chip", title: o.includes(".") ? `status ${o.split(".")[0]}, raising int:${name}.${o.split(".")[1]}` : `status ${o}` }, cb, " ", o);
      }))));
      if (!readOnly()) {
        const rm = el("button", { class: "danger" }, "delete task");
        rm.addEventListener("click", () => app.edit((d) => { delete d.tasks[name]; }));
        box.append(el("p", {}, rm));
      }
      tasksPanel.append(box);
    }
    if (!Object.keys(draft.tasks).length) tasksPanel.append(el("p", { class: "empty" }, "no primitive tasks yet: set a place's kind to primitive_task"));
    if (!readOnly()) {
      const nameIn = el("input", { type: "text", placeholder: "task name", size: 14 });
      const add = el("button", {}, "+ task");
      add.addEventListener("click", () => {
        const n = nameIn.value.trim();
        if (!NAME_RE.test(n)) { app.message("task names use letters, digits and '_', starting with a letter or '_'", "bad"); return; }
        app.edit((d) => { if (!(n in d.tasks)) d.tasks[n] = { actions: ["echo"] }; });
      });
      tasksPanel.append(el("p", {}, nameIn, " ", add));
    }
    // external events and their publishers
    const topics = [...new Set(draft.transitions.flatMap((t) => (t.events || []).filter((e) => e.startsWith("ext:"))))];
    if (topics.length) {
      tasksPanel.append(el("h4", {}, "external events"));
      const table = el("table", { class: "grid" }, el("tr", {}, el("th", {}, "event"), el("th", {}, "published by")));
      for (const e of topics) {
        const node = placement[e];
        table.append(el("tr", {}, el("td", { class: "mono" }, e), !hasPlacement ? el("td", {}, "?") :
          node ? el("td", { class: "node-ok" }, node) : el("td", { class: "unplaced" }, "no publisher")));
      }
      tasksPanel.append(table);
    }
  }
  app.renderTasks = renderTasks;

  /** Give or take a right of the net's [operator] table (inject an event; force an outcome of a task). */
  function setRights(d, which, value, on, task = null) {
    const rights = d.operator || {};
    if (which === "inject") {
      const list = new Set(rights.inject || []);
      if (on) list.add(value); else list.delete(value);
      if (list.size) rights.inject = [...list]; else delete rights.inject;
    } else {
      const force = { ...(rights.force || {}) };
      const list = new Set(force[task] || []);
      if (on) list.add(value); else list.delete(value);
      if (list.size) force[task] = [...list]; else delete force[task];
      if (Object.keys(force).length) rights.force = force; else delete rights.force;
    }
    if (Object.keys(rights).length) d.operator = rights; else delete d.operator;
  }

  function editAction(task, index, change) {
    app.edit((d) => {
      const list = d.tasks[task].actions;
      let spec = typeof list[index] === "string" ? { name: list[index] } : { ...list[index] };
      for (const [k, v] of Object.entries(change)) { if (v === null) delete spec[k]; else spec[k] = v; }
      list[index] = Object.keys(spec).length === 1 && "name" in spec ? spec.name : spec;
    });
  }

  setTool("select");
  return { renderInspector, renderTasks, setTool };
}
