// The drawing: cytoscape.js elements made from the draft, with a plane of small page elements over it
// for everything that changes while a run goes (tokens, flashes of fired transitions, running actions'
// badges) and for the marks the operator clicks (analyses' numbers linked to their definitions,
// breakpoints, hidden error branches). The draft stays the one source of truth; sync() makes the
// drawing follow it.
//
// The plane is moved with the viewport by one CSS transform: a run that moves tokens and fires
// transitions hundreds of times a second changes a few small elements per screen frame, and
// cytoscape's whole-canvas redraw (and the canvas copy the browser makes after it) happens only when
// the drawing itself changes (an edit, a pan, an analysis shown).
//
// Labels: a place shows its id, then its primitive task or a short form of its label; a transition its
// id, then its events ("names first, events second": the ids the terminal, the journal and the
// commands use). Tidy lays the net out with ELK's layered algorithm on boxes that hold each node and
// its label, so that no label overlaps another label or node (labelOverlaps() counts them).

import { arcKey, hiddenSet } from "./net.js";

const PLACE_D = 46;
const TRANS_W = 46, TRANS_H = 12;
const FONT = 16;             // model units: readable at the zoom Fit gives the paper's nets at 1400x900
// ---- token images: dots like Fig. 1 for a few tokens, the number beyond
const tokenCache = new Map();
export function tokenImage(n) {
  const key = String(n);
  if (tokenCache.has(key)) return tokenCache.get(key);
  const dots = {
    1: [[22, 22]], 2: [[15, 22], [29, 22]], 3: [[22, 14], [14, 28], [30, 28]],
    4: [[15, 15], [29, 15], [15, 29], [29, 29]], 5: [[14, 14], [30, 14], [22, 22], [14, 30], [30, 30]],
  }[n];
  let body;
  if (dots) body = dots.map(([x, y]) => `<circle cx="${x}" cy="${y}" r="4.6" fill="#111"/>`).join("");
  else body = `<text x="22" y="28.5" font-family="Arial, sans-serif" font-size="${n > 999 ? 11 : 16}" font-weight="700" text-anchor="middle" fill="#111">${n > 99999 ? "99k+" : n}</text>`;
  const svg = `<svg xmlns="http://www.w3.org/2000/svg" width="44" height="44" viewBox="0 0 44 44">${body}</svg>`;
  const uri = "data:image/svg+xml;utf8," + encodeURIComponent(svg);
  tokenCache.set(key, uri);
  return uri;
}

function placeLabel(p) {
  // one line: the id (the terminal's, the journal's, the commands'), the task of a primitive-task
  // place; the label in full on hover
  return placeKind(p) === "primitive_task" ? `${p.id} [${p.task || "?"}]` : p.id;
}

function transitionLabel(t, mode) {
  const events = (t.events || []).join("  ");
  if (mode === "events") return events || t.id;
  if (mode === "names") return t.id;
  return events ? `${t.id}\n${events}` : t.id;     // names first, events second
}

/** Cycle the transition labels: names and events -> names -> events (as in the paper's Fig. 1). */
export function nextLabelMode(mode) { return { both: "names", names: "events", events: "both" }[mode] || "both"; }

function placeKind(p) { return p.kind || (p.task ? "primitive_task" : "plain"); }

const STYLE = [
  { selector: "node", style: { "font-size": FONT, color: "#1d232b", "text-wrap": "wrap", "text-max-width": 190,
                               "min-zoomed-font-size": 5, "text-background-color": "#fff", "text-background-opacity": 0.85,
                               "text-background-padding": 1.5, "text-background-shape": "roundrectangle" } },
  { selector: "node.place", style: {
      shape: "ellipse", width: PLACE_D, height: PLACE_D, "background-color": "#fff", "border-width": 1.6,
      "border-color": "#555", label: "data(label)", "text-valign": "bottom", "text-margin-y": 4 } },
  { selector: "node.place.resource", style: { "background-color": "#d6e6ff", "border-color": "#2f5fa7", "border-width": 2 } },
  { selector: "node.place.primitive_task", style: { "background-color": "#fff0a8", "border-color": "#9a6b00",
                                                    "border-width": 5, "border-style": "double" } },
  { selector: "node.place.control", style: { "background-color": "#e3e3e3", "border-color": "#222", "border-width": 3.5 } },
  { selector: "node.place.busy", style: { "border-color": "#d46b08" } },
  { selector: "node.transition", style: {
      shape: "rectangle", width: TRANS_W, height: TRANS_H, "background-color": "#2b2f36", "border-width": 0,
      label: "data(label)", "text-halign": "right", "text-valign": "center", "text-margin-x": 6,
      "text-justification": "left", color: "#27303a" } },
  { selector: "node.transition.exponential", style: { "background-color": "#fff", "border-width": 1.6, "border-color": "#2b2f36" } },
  { selector: ".hidden-branch", style: { opacity: 0.55 } },
  { selector: "node.transition.hidden-branch", style: { "background-color": "#8c959f", "border-style": "dashed" } },
  { selector: "edge", style: {
      width: 1.5, "line-color": "#5b6570", "target-arrow-color": "#5b6570", "target-arrow-shape": "triangle",
      "arrow-scale": 0.9, "curve-style": "bezier", label: "data(label)", "font-size": 11, color: "#1d232b",
      "text-background-color": "#fff", "text-background-opacity": 1, "text-background-padding": 1 } },
  { selector: "edge.back", style: { "curve-style": "unbundled-bezier", "control-point-distances": "data(bend)",
                                    "control-point-weights": 0.5 } },
  { selector: "edge.inhibitor", style: { "target-arrow-shape": "circle", "target-arrow-fill": "hollow", "arrow-scale": 1.1 } },
  { selector: "edge.reset", style: { "line-style": "dashed", "target-arrow-shape": "tee", "line-dash-pattern": [6, 3],
                                     "line-color": "#7a4fb0", "target-arrow-color": "#7a4fb0" } },
  { selector: "edge.hidden-branch", style: { "line-style": "dashed", "line-color": "#8c959f", "target-arrow-color": "#8c959f" } },
  { selector: "node.place.failing", style: { "border-color": "#cf222e", "underlay-color": "#cf222e", "underlay-opacity": 0.25,
                                             "underlay-padding": 8, "underlay-shape": "ellipse" } },
  { selector: "node.transition.failing", style: { "background-color": "#cf222e", "underlay-color": "#cf222e",
                                                  "underlay-opacity": 0.22, "underlay-padding": 6 } },
  // analyses drawn on the net (analysis.js)
  { selector: "node.heat", style: { "underlay-color": "data(heat)", "underlay-opacity": 0.75, "underlay-padding": 9 } },
  { selector: "node.place.heat", style: { "underlay-shape": "ellipse" } },
  { selector: "node.bottleneck", style: { "underlay-color": "#cf222e", "underlay-opacity": 0.9, "underlay-padding": 11 } },
  { selector: "node.transition.dead", style: { "background-color": "#fff", "border-width": 2, "border-color": "#cf222e",
                                               "border-style": "dashed" } },
  { selector: "node.transition.notlive", style: { "border-width": 2, "border-color": "#d46b08" } },
  { selector: ".inv", style: { "underlay-color": "#8250df", "underlay-opacity": 0.45, "underlay-padding": 9 } },
  { selector: "edge.trace", style: { "line-color": "#cf222e", "target-arrow-color": "#cf222e", width: 3 } },
  { selector: ".problem", style: { "underlay-color": "#cf222e", "underlay-opacity": 0.28, "underlay-padding": 6 } },
  { selector: "edge.problem", style: { "line-color": "#cf222e", "target-arrow-color": "#cf222e" } },
  { selector: ":selected", style: { "overlay-color": "#1f6feb", "overlay-opacity": 0.18, "overlay-padding": 6 } },
  { selector: "node.arc-source", style: { "overlay-color": "#1a7f37", "overlay-opacity": 0.3, "overlay-padding": 8 } },
  { selector: "node.steerable", style: { "underlay-color": "#1f6feb", "underlay-opacity": 0.12, "underlay-padding": 8,
                                         "underlay-shape": "ellipse" } },
];

export class Graph {
  constructor(container) {
    this.cy = cytoscape({ container, style: STYLE, minZoom: 0.05, maxZoom: 4,
                          boxSelectionEnabled: true, selectionType: "single", textureOnViewport: false,
                          pixelRatio: "auto" });
    this.showHidden = true;
    this.labelMode = "both";      // names first, events second
    this.tokens = new Map();      // place id -> shown count
    this.plane = new Plane(this.cy, container);
    this.flashTimer = null;
    this.flashing = new Set();
    this.badges = new Map();      // place id -> {text, latched, failing}
    this.failing = { places: [], transitions: [] };  // a run's failing primitive tasks: places, error branches
    this.marks = [];              // [{key, node, text, href, title, cls, at}] drawn beside nodes
    this.onReveal = null;         // called when the operator clicks a hidden-branch mark
    this.draft = null;
  }

  /** Make the drawing follow the draft (adds, removes and updates elements). */
  sync(draft, { marking = null, fit = false } = {}) {
    this.draft = draft;
    const cy = this.cy;
    const hidden = hiddenSet(draft);
    const wanted = new Map();
    for (const p of draft.places) {
      if (typeof p.id !== "string") continue;
      const kind = placeKind(p);
      wanted.set(p.id, { group: "nodes", data: { id: p.id, label: placeLabel(p), kind: "place" },
        position: pos(p), classes: `place ${kind}${hidden.places.has(p.id) ? " hidden-branch" : ""}` });
    }
    for (const t of draft.transitions) {
      if (typeof t.id !== "string") continue;
      const cls = `transition${t.kind === "exponential" ? " exponential" : ""}${t.hidden === true ? " hidden-branch" : ""}`;
      wanted.set(t.id, { group: "nodes", data: { id: t.id, label: transitionLabel(t, this.labelMode), kind: "transition" },
        position: pos(t), classes: cls });
    }
    const hiddenOf = (a) => hidden.transitions.has(a.from) || hidden.transitions.has(a.to);
    for (const a of draft.arcs) {
      if (!wanted.has(a.from) || !wanted.has(a.to)) continue;
      const key = "arc:" + arcKey(a);
      const w = a.weight ?? 1;
      const kind = a.inhibitor ? "inhibitor" : a.reset ? "reset" : "";
      wanted.set(key, { group: "edges", data: { id: key, source: a.from, target: a.to,
        label: w !== 1 && !a.reset ? String(w) : "", kind: "arc", key: arcKey(a) }, classes: `${kind}${hiddenOf(a) ? " hidden-branch" : ""}` });
    }
    cy.batch(() => {
      cy.elements().forEach((el) => {
        const want = wanted.get(el.id());
        const sameEnds = !want || want.group !== "edges" ||
          (el.data("source") === want.data.source && el.data("target") === want.data.target);
        if (!want || !sameEnds) el.remove();
      });
      for (const [id, want] of wanted) {
        const el = cy.getElementById(id);
        if (el.empty()) {
          cy.add(want);
        } else {
          el.data(want.data);
          const keep = ["failing", "heat", "bottleneck", "dead", "notlive", "inv", "trace", "problem", "busy", "arc-source"]
            .filter((c) => el.hasClass(c));
          el.classes(want.classes + (keep.length ? " " + keep.join(" ") : ""));
          if (want.group === "nodes") {
            const p = el.position();
            if (Math.abs(p.x - want.position.x) > 0.01 || Math.abs(p.y - want.position.y) > 0.01) el.position(want.position);
          }
        }
      }
      this.applyHidden();
      this.bendBackArcs();
      this.applyFailing();
    });
    const start = marking || Object.fromEntries(draft.places.filter((p) => Number.isInteger(p.tokens) && p.tokens > 0)
      .map((p) => [p.id, p.tokens]));
    this.setMarking(start, true);
    this.refreshBadges();
    this.refreshMarks();
    if (fit) this.fit();
  }

  /** Arcs that climb a long way (back to an earlier stage: a resource returned, a run restarted)
   *  bow out towards the nearer side of the drawing instead of cutting through it. */
  bendBackArcs() {
    const cy = this.cy;
    const nodes = cy.nodes();
    if (!nodes.length || cy.edges().length > 3000) return;
    const bb = nodes.boundingBox({ includeLabels: false });
    const mid = (bb.x1 + bb.x2) / 2;
    cy.edges().forEach((e) => {
      const a = e.source().position(), b = e.target().position();
      const rise = a.y - b.y;
      const length = Math.hypot(rise, b.x - a.x);
      if (rise < 160 || length < 1) { e.removeClass("back"); return; }
      const outward = (a.x + b.x) / 2 >= mid ? 1 : -1;   // the side of the line away from the middle
      e.data("bend", outward * Math.min(220, 0.25 * length));
      e.addClass("back");
    });
  }

  /** Fit the visible net in the canvas (labels included), never zoomed in beyond 1.6. */
  fit() {
    const cy = this.cy;
    const shown = cy.elements(":visible");
    if (!shown.length) return;
    cy.fit(shown, 24);
    if (cy.zoom() > 1.6) { cy.zoom(1.6); cy.center(shown); }
  }

  applyHidden() {
    const show = this.showHidden;
    this.cy.elements(".hidden-branch").style("display", show ? "element" : "none");
    this.plane.refresh();
    this.refreshMarks();
  }

  setShowHidden(show) { this.showHidden = show; this.cy.batch(() => this.applyHidden()); }

  /** Show a marking: `changes` maps place ids to counts; `full` replaces every count. */
  setMarking(changes, full = false) {
    if (full) {
      changes = { ...changes };
      this.cy.nodes(".place").forEach((n) => { if (!(n.id() in changes)) changes[n.id()] = 0; });
      for (const id of this.tokens.keys()) if (!(id in changes)) changes[id] = 0;
    }
    for (const [id, n] of Object.entries(changes)) {
      if (this.tokens.get(id) === n) continue;
      if (n > 0) this.tokens.set(id, n); else this.tokens.delete(id);
      this.plane.token(id, n);
    }
  }

  /** Flash the given transitions for a moment (page elements over the canvas; one timer). */
  flash(ids) {
    for (const id of ids) {
      if (this.flashing.has(id)) continue;  // still lit from an earlier frame
      this.flashing.add(id);
      this.plane.flash(id, true);
    }
    clearTimeout(this.flashTimer);
    this.flashTimer = setTimeout(() => {
      for (const id of this.flashing) this.plane.flash(id, false);
      this.flashing.clear();
    }, 280);
  }

  /** Badges beside places: Map place id -> {text, latched, failing}. */
  setBadges(map) {
    this.badges = map;
    this.refreshBadges();
  }

  refreshBadges() {
    const cy = this.cy;
    this.plane.badges(this.badges);
    const busy = [...this.badges].filter(([, b]) => !b.latched && !b.failing).map(([id]) => id);
    const now = new Set(busy);
    const stale = cy.nodes(".place.busy").filter((n) => !now.has(n.id()));
    const fresh = busy.filter((id) => !cy.getElementById(id).hasClass("busy"));
    if (stale.length || fresh.length) {
      cy.batch(() => { stale.removeClass("busy"); for (const id of fresh) cy.getElementById(id).addClass("busy"); });
    }
  }

  /** Mark the places of primitive tasks whose last results were errors, and their error branches. */
  setFailing(places, transitions) {
    this.failing = { places, transitions };
    this.cy.batch(() => this.applyFailing());
  }

  applyFailing() {
    const cy = this.cy;
    const want = new Set([...this.failing.places, ...this.failing.transitions]);
    cy.nodes(".failing").forEach((n) => { if (!want.has(n.id())) n.removeClass("failing"); });
    for (const id of want) cy.getElementById(id).addClass("failing");
  }

  /** Mark elements with problems: set of node ids and arc keys. */
  setProblems(ids) {
    const cy = this.cy;
    cy.batch(() => {
      cy.elements(".problem").removeClass("problem");
      for (const id of ids) {
        const el = cy.getElementById(id).nonempty() ? cy.getElementById(id) : cy.getElementById("arc:" + id);
        el.addClass("problem");
      }
    });
  }

  /** Marks beside nodes (analyses, breakpoints): [{key, node, text, href?, title?, cls?, at?, onclick?}]. */
  setMarks(group, marks) {
    this.marks = this.marks.filter((m) => m.group !== group).concat(marks.map((m) => ({ ...m, group })));
    this.refreshMarks();
  }

  refreshMarks() {
    const chips = [];
    if (!this.showHidden && this.draft) {
      // hidden error branches stay one click away: a mark on each place whose branches are hidden
      const hidden = hiddenSet(this.draft);
      const count = new Map();
      for (const a of this.draft.arcs) {
        if (hidden.transitions.has(a.to) && !hidden.places.has(a.from)) count.set(a.from, (count.get(a.from) || 0) + 1);
      }
      for (const [place, n] of count) {
        chips.push({ group: "hidden", key: `hidden:${place}`, node: place, at: "corner-left", cls: "reveal",
                     text: `\u2295${n}`, title: `${n} hidden error-recovery branch${n === 1 ? "" : "es"} leave ${place}: click to show them`,
                     onclick: () => { this.setShowHidden(true); if (this.onReveal) this.onReveal(place); } });
      }
    }
    this.plane.marks([...this.marks, ...chips]);
  }

  positions() {
    const out = {};
    this.cy.nodes().forEach((n) => { const p = n.position(); out[n.id()] = [Math.round(p.x * 10) / 10, Math.round(p.y * 10) / 10]; });
    return out;
  }

  /** Every node's body and label boxes (model units), the visible ones. */
  boxes() {
    const out = [];
    this.cy.nodes(":visible").forEach((n) => {
      const body = n.boundingBox({ includeLabels: false, includeOverlays: false, includeUnderlays: false });
      const label = n.data("label") ? n.boundingBox({ includeNodes: false, includeEdges: false, includeLabels: true,
                                                      includeOverlays: false, includeUnderlays: false }) : null;
      out.push({ id: n.id(), body, label: label && label.w > 0 ? label : null });
    });
    this.cy.edges(":visible").forEach((e) => {
      if (!e.data("label")) return;
      const label = e.boundingBox({ includeNodes: false, includeEdges: false, includeLabels: true, includeOverlays: false });
      if (label.w > 0) out.push({ id: e.id(), body: null, label, edge: [e.source().id(), e.target().id()] });
    });
    return out;
  }

  /** Labels overlapped by another label or by a node (pairs counted once), with a tolerance of 1 unit. */
  labelOverlaps() {
    const boxes = this.boxes();
    const hit = (a, b) => a && b && a.x1 < b.x2 - 1 && b.x1 < a.x2 - 1 && a.y1 < b.y2 - 1 && b.y1 < a.y2 - 1;
    const found = [];
    for (let i = 0; i < boxes.length; i++) {
      const a = boxes[i];
      if (!a.label) continue;
      for (let j = 0; j < boxes.length; j++) {
        if (i === j) continue;
        const b = boxes[j];
        if (a.edge && a.edge.includes(b.id)) continue;   // an arc's weight sits on its own ends' line
        if (j > i && hit(a.label, b.label)) found.push([a.id, b.id, "label"]);
        if (hit(a.label, b.body)) found.push([a.id, b.id, "node"]);
      }
    }
    return found;
  }

  /** How much of the canvas the fitted drawing fills, and the smallest label on screen, px. */
  readability() {
    const cy = this.cy;
    const bb = cy.elements(":visible").boundingBox();
    const z = cy.zoom();
    return { fill: Math.max(bb.w * z / cy.width(), bb.h * z / cy.height()), fontPx: FONT * z, zoom: z };
  }

  /** Lay the drawing out with ELK (layered, each node boxed with its label so that no label overlaps
   *  another label or node, the layout that fits the canvas at the largest zoom); resolves with the new
   *  positions of every node. While the error-recovery branches are hidden, the net without them is
   *  laid out on its own (what the operator reads) and the branches in a band below it. */
  async tidy() {
    const cy = this.cy;
    const wasShown = this.showHidden;
    if (!wasShown) this.setShowHidden(true);  // measure every label
    const hiddenNodes = cy.nodes(".hidden-branch");
    const parts = wasShown || hiddenNodes.empty() ? [cy.nodes()] : [cy.nodes().not(".hidden-branch"), hiddenNodes];
    const positions = {};
    let top = 0;
    for (const part of parts) {
      const laid = await this.layOut(part);
      const ys = Object.values(laid).map((p) => p[1]);
      const shift = top - Math.min(...ys);
      for (const [id, [x, y]] of Object.entries(laid)) positions[id] = [x, Math.round((y + shift) * 10) / 10];
      const bottom = Math.max(...part.map((n) => positions[n.id()][1] + n.boundingBox({ includeLabels: true }).h));
      top = bottom + 60;
    }
    cy.batch(() => { cy.nodes().forEach((n) => { const p = positions[n.id()]; if (p) n.position({ x: p[0], y: p[1] }); }); });
    this.bendBackArcs();
    if (!wasShown) this.setShowHidden(false);
    this.plane.refresh();
    this.fit();
    return positions;
  }

  /** ELK positions (node centres, model units) of ``nodes`` and the arcs among them. */
  async layOut(nodes) {
    const cy = this.cy;
    const ids = new Set(nodes.map((n) => n.id()));
    const margin = 6;
    const children = [];
    const offsets = new Map();
    // the model order ELK keeps: the initially marked places first, then a depth-first walk from them,
    // so that the arcs closing cycles (a resource given back, a run started again) are the ones turned
    // around and the drawing starts where the tokens are, as a hand drawing of a task does
    const order = [];
    const seen = new Set();
    const walk = (start) => {
      const stack = [start];
      while (stack.length) {
        const n = stack.pop();
        if (seen.has(n.id()) || !ids.has(n.id())) continue;
        seen.add(n.id());
        order.push(n);
        for (const m of n.outgoers("node").toArray().reverse()) if (!seen.has(m.id())) stack.push(m);
      }
    };
    const marked = nodes.filter((n) => n.hasClass("place") && this.tokens.get(n.id()) > 0);
    marked.forEach((n) => { seen.add(n.id()); order.push(n); });
    marked.forEach((n) => n.outgoers("node").forEach(walk));
    nodes.forEach(walk);
    for (const n of order) {
      const bb = n.boundingBox({ includeLabels: true, includeOverlays: false, includeUnderlays: false });
      const p = n.position();
      offsets.set(n.id(), { x: p.x - bb.x1 + margin, y: p.y - bb.y1 + margin });
      children.push({ id: n.id(), width: bb.w + 2 * margin, height: bb.h + 2 * margin });
    }
    const edges = [];
    cy.edges().forEach((e) => {
      if (ids.has(e.data("source")) && ids.has(e.data("target"))) {
        edges.push({ id: e.id(), sources: [e.data("source")], targets: [e.data("target")] });
      }
    });
    const aspect = Math.max(0.5, Math.min(3, cy.width() / Math.max(1, cy.height())));
    const options = (direction, wrap) => ({
      "elk.algorithm": "layered", "elk.direction": direction, "elk.aspectRatio": String(aspect),
      "elk.spacing.nodeNode": "10", "elk.layered.spacing.nodeNodeBetweenLayers": "14",
      "elk.spacing.edgeNode": "8", "elk.layered.spacing.edgeNodeBetweenLayers": "8",
      "elk.layered.cycleBreaking.strategy": "MODEL_ORDER",
      // network simplex places nodes best, but takes seconds beyond a hundred nodes
      "elk.layered.nodePlacement.strategy": children.length <= 100 ? "NETWORK_SIMPLEX" : "BRANDES_KOEPF",
      "elk.layered.considerModelOrder.strategy": "NODES_AND_EDGES",
      "elk.layered.wrapping.strategy": wrap ? "MULTI_EDGE" : "OFF",
      "elk.separateConnectedComponents": "true", "elk.spacing.componentComponent": "30",
      });
    // top to bottom as the paper draws its nets, or left to right, each also folded into rows or
    // columns (ELK's wrapping, for a long net): the one that fits the canvas at a clearly larger zoom
    const elk = new ELK();
    const tries = [["DOWN", false], ["RIGHT", false], ["DOWN", true], ["RIGHT", true]];
    const layouts = await Promise.all(tries.map(([direction, wrap]) =>
      elk.layout({ id: "root", children: children.map((c) => ({ ...c })), edges: edges.map((e) => ({ ...e })),
                   layoutOptions: options(direction, wrap) })));
    const zoomOf = (g) => Math.min(cy.width() / Math.max(1, g.width), cy.height() / Math.max(1, g.height));
    let out = layouts[0];
    for (const g of layouts.slice(1)) if (zoomOf(g) > 1.15 * zoomOf(out)) out = g;
    this.lastTidy = layouts.map((g, i) => [tries[i].join(" "), Math.round(g.width), Math.round(g.height), zoomOf(g)]);
    const positions = {};
    for (const c of out.children) {
      const o = offsets.get(c.id);
      positions[c.id] = [Math.round((c.x + o.x) * 10) / 10, Math.round((c.y + o.y) * 10) / 10];
    }
    return positions;
  }

  /** The whole drawing as a PNG data URL (2 px per model unit), tokens included: cytoscape draws
   *  the net, the tokens are drawn over it where cytoscape's own export put their places. */
  async png() {
    const cy = this.cy;
    const scale = 2 * (window.devicePixelRatio || 1);   // cytoscape's png({scale: 2}) on this screen
    const bb = cy.mutableElements().boundingBox();       // the region cytoscape's full export draws
    const base = await loadImage(cy.png({ full: true, scale: 2, bg: "#ffffff" }));
    const canvas = document.createElement("canvas");
    canvas.width = base.width;
    canvas.height = base.height;
    const ctx = canvas.getContext("2d");
    ctx.drawImage(base, 0, 0);
    for (const [id, n] of this.tokens) {
      const node = cy.getElementById(id);
      if (node.empty() || !node.visible()) continue;
      const p = node.position();
      const img = await loadImage(tokenImage(n));
      ctx.globalAlpha = Number(node.style("opacity")) || 1;   // faded with a hidden branch's place
      ctx.drawImage(img, (p.x - 22 - bb.x1) * scale, (p.y - 22 - bb.y1) * scale, 44 * scale, 44 * scale);
    }
    return canvas.toDataURL("image/png");
  }
}

function loadImage(src) {
  return new Promise((resolve, reject) => {
    const img = new Image();
    img.onload = () => resolve(img);
    img.onerror = () => reject(new Error("an image of the drawing did not load"));
    img.src = src;
  });
}

/** Small page elements over cytoscape's canvas, placed in model coordinates on a plane that one CSS
 *  transform keeps on cytoscape's pan and zoom: tokens (one per marked place), flashes of fired
 *  transitions, badges of running actions, and marks (links, breakpoints, hidden-branch chips). */
class Plane {
  constructor(cy, container) {
    this.cy = cy;
    this.layer = document.createElement("div");
    this.layer.className = "token-layer";
    this.plane = document.createElement("div");
    this.plane.className = "token-plane";
    this.layer.append(this.plane);
    this.marksLayer = document.createElement("div");
    this.marksLayer.className = "mark-layer";
    this.marksPlane = document.createElement("div");
    this.marksPlane.className = "token-plane";
    this.marksLayer.append(this.marksPlane);
    container.after(this.layer, this.marksLayer);
    this.dots = new Map();    // place id -> element
    this.flashes = new Map(); // transition id -> element
    this.badgeEls = new Map(); // place id -> element
    this.markEls = new Map();  // key -> {el, mark}
    cy.on("viewport resize", () => this.follow());
    cy.on("position", "node", (ev) => this.place(ev.target.id()));
    cy.on("add remove data", "node", (ev) => this.place(ev.target.id()));
    cy.on("style", "node", (ev) => this.place(ev.target.id()));
    this.follow();
  }

  follow() {
    const pan = this.cy.pan(), zoom = this.cy.zoom();
    const t = `translate(${pan.x}px, ${pan.y}px) scale(${zoom})`;
    this.plane.style.transform = t;
    this.marksPlane.style.transform = t;
  }

  /** Show ``n`` tokens on place ``id`` (0: none). */
  token(id, n) {
    let dot = this.dots.get(id);
    if (!n) { if (dot) { dot.remove(); this.dots.delete(id); } return; }
    if (!dot) {
      dot = document.createElement("div");
      dot.className = "tokens";
      dot.dataset.place = id;
      this.plane.append(dot);
      this.dots.set(id, dot);
      this.place(id);
    }
    dot.style.backgroundImage = `url("${tokenImage(n)}")`;
  }

  flash(id, on) {
    let el = this.flashes.get(id);
    if (!on) { if (el) el.style.display = "none"; return; }
    if (!el) {
      el = document.createElement("div");
      el.className = "flash";
      el.dataset.transition = id;
      this.plane.prepend(el);
      this.flashes.set(id, el);
    }
    el.style.display = "";
    this.placeFlash(id, el);
  }

  badges(map) {
    for (const [id, el] of this.badgeEls) if (!map.has(id)) { el.remove(); this.badgeEls.delete(id); }
    for (const [id, b] of map) {
      let el = this.badgeEls.get(id);
      if (!el) {
        el = document.createElement("div");
        el.dataset.place = id;
        this.plane.append(el);
        this.badgeEls.set(id, el);
      }
      const cls = "badge" + (b.latched ? " latched" : "") + (b.failing ? " failing" : "");
      if (el.className !== cls) el.className = cls;
      if (el.textContent !== b.text) el.textContent = b.text;
      this.placeBadge(id, el);
    }
  }

  marks(list) {
    const keys = new Set(list.map((m) => m.key));
    for (const [key, { el }] of this.markEls) if (!keys.has(key)) { el.remove(); this.markEls.delete(key); }
    for (const mark of list) {
      let entry = this.markEls.get(mark.key);
      if (!entry || entry.mark.href !== mark.href) {
        if (entry) entry.el.remove();
        const el = document.createElement(mark.href ? "a" : mark.onclick ? "button" : "span");
        if (mark.href) { el.href = mark.href; el.target = "_blank"; el.rel = "noopener"; }
        this.marksPlane.append(el);
        entry = { el, mark };
        this.markEls.set(mark.key, entry);
      }
      entry.mark = mark;
      const el = entry.el;
      el.className = "mark " + (mark.cls || "");
      if (mark.bars) {
        // a learner's probabilities: one small bar per action, its length the probability
        const key = JSON.stringify(mark.bars);
        if (el.dataset.bars !== key) {
          el.dataset.bars = key;
          el.replaceChildren(...mark.bars.map(([name, p]) => {
            const row = document.createElement("span");
            row.className = "lbar";
            const bar = document.createElement("i");
            bar.style.width = `${Math.max(1, Math.round((p || 0) * 50))}px`;
            row.append(bar, `${name} ${Number.isFinite(p) ? p.toFixed(2) : "-"}`);
            return row;
          }));
        }
      } else if (el.textContent !== mark.text) el.textContent = mark.text;
      el.title = mark.title || "";
      el.dataset.node = mark.node;
      el.dataset.key = mark.key;
      el.onclick = mark.onclick ? (ev) => { ev.preventDefault(); ev.stopPropagation(); mark.onclick(); } : null;
      this.placeMark(entry);
    }
  }

  /** Put what belongs to node ``id`` where the node is drawn (hidden with it, faded with it). */
  place(id) {
    const node = this.cy.getElementById(id);
    const gone = node.empty() || node.removed() || node.style("display") === "none";
    const dot = this.dots.get(id);
    if (dot) {
      if (gone) dot.style.display = "none";
      else {
        const p = node.position();
        dot.style.display = "";
        dot.style.transform = `translate(${p.x - 22}px, ${p.y - 22}px)`;
        dot.style.opacity = node.style("opacity");
      }
    }
    const flash = this.flashes.get(id);
    if (flash && flash.style.display !== "none") this.placeFlash(id, flash);
    const badge = this.badgeEls.get(id);
    if (badge) this.placeBadge(id, badge);
    for (const entry of this.markEls.values()) if (entry.mark.node === id) this.placeMark(entry);
  }

  placeFlash(id, el) {
    const node = this.cy.getElementById(id);
    if (node.empty() || node.style("display") === "none") { el.style.display = "none"; return; }
    const p = node.position();
    el.style.transform = `translate(${p.x - TRANS_W / 2 - 7}px, ${p.y - TRANS_H / 2 - 7}px)`;
  }

  placeBadge(id, el) {
    const node = this.cy.getElementById(id);
    if (node.empty() || node.style("display") === "none") { el.style.display = "none"; return; }
    const p = node.position();
    el.style.display = "";
    el.style.transform = `translate(${p.x + PLACE_D / 2 + 6}px, ${p.y - PLACE_D / 2 - 10}px)`;
  }

  placeMark(entry) {
    const { el, mark } = entry;
    const node = this.cy.getElementById(mark.node);
    if (node.empty() || node.style("display") === "none") { el.style.display = "none"; return; }
    const p = node.position();
    const place = node.data("kind") === "place";
    const half = place ? PLACE_D / 2 : TRANS_W / 2;
    const at = mark.at || "above";
    let x = p.x, y = p.y;
    if (at === "above") { x = p.x - half; y = p.y - (place ? PLACE_D / 2 : TRANS_H / 2) - 17; }
    else if (at === "left") { x = p.x - half - 4; y = p.y - 8; el.style.translate = "-100% 0"; }
    else if (at === "right") { x = p.x + half + 4; y = p.y - 8; }
    else if (at === "below-left") { x = p.x - half - 4; y = p.y + (place ? PLACE_D / 2 : TRANS_H / 2) - 6; el.style.translate = "-100% 0"; }
    else if (at === "center") { x = p.x; y = p.y; el.style.translate = "-50% -50%"; }
    else if (at === "corner-left") { x = p.x - half + 2; y = p.y - (place ? PLACE_D / 2 : TRANS_H / 2) + 2; el.style.translate = "-100% -100%"; }
    else if (at === "corner-right") { x = p.x + half - 2; y = p.y - (place ? PLACE_D / 2 : TRANS_H / 2) + 2; el.style.translate = "0 -100%"; }
    if (!["left", "below-left", "center", "corner-left", "corner-right"].includes(at)) el.style.translate = "";
    el.style.display = "";
    el.style.transform = `translate(${x}px, ${y}px)`;
  }

  refresh() {
    const ids = new Set([...this.dots.keys(), ...this.flashes.keys(), ...this.badgeEls.keys(),
                         ...[...this.markEls.values()].map((e) => e.mark.node)]);
    for (const id of ids) this.place(id);
    this.follow();
  }
}

function pos(item) {
  const p = item.pos;
  if (Array.isArray(p) && p.length === 2 && Number.isFinite(p[0]) && Number.isFinite(p[1])) return { x: p[0], y: p[1] };
  return { x: 0, y: 0 };
}
