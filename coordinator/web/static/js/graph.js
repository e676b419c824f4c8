// The drawing: cytoscape.js elements made from the draft, tokens as dots, flashes of fired transitions,
// badges of running actions. The draft stays the one source of truth; sync() makes the drawing follow it.
//
// Tokens live on a layer of small HTML elements above cytoscape's canvas, one per marked place, moved
// with the viewport by one CSS transform: a run that moves tokens hundreds of times a second changes
// a few small elements per screen frame, and cytoscape's whole-canvas redraw (and the canvas copy the
// browser makes after it) happens only when the drawing itself changes.

import { arcKey, hiddenSet } from "./net.js";

const PLACE_D = 46;
const TRANS_W = 46, TRANS_H = 12;

// ---- token images: dots like Fig. 1 for a few tokens, the number beyond
const tokenCache = new Map();
function tokenImage(n) {
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
  const name = p.label || p.id;
  return p.kind === "primitive_task" || (p.task && !p.kind) ? `${name}\n[${p.task || "?"}]` : name;
}

function transitionLabel(t, mode) {
  const events = (t.events || []).join("  ");
  const name = t.label || t.id;
  if (mode === "events") return events || name;
  if (mode === "names") return name;
  return events ? `${events}\n${name}` : name;
}

/** Cycle the transition labels: events (Fig. 1) -> events and names -> names. */
export function nextLabelMode(mode) { return { events: "both", both: "names", names: "events" }[mode] || "events"; }

function placeKind(p) { return p.kind || (p.task ? "primitive_task" : "plain"); }

const STYLE = [
  { selector: "node", style: { "font-size": 11, color: "#1d232b", "text-wrap": "wrap", "text-max-width": 170,
                               "min-zoomed-font-size": 6, "text-background-color": "#fff", "text-background-opacity": 0.8,
                               "text-background-padding": 1 } },
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
      "font-size": 10.5, color: "#3a4450" } },
  { selector: "node.transition.exponential", style: { "background-color": "#fff", "border-width": 1.6, "border-color": "#2b2f36" } },
  { selector: "node.transition.fired", style: { "background-color": "#ff8c00", "underlay-color": "#ff8c00",
                                                "underlay-opacity": 0.35, "underlay-padding": 7, "underlay-shape": "round-rectangle" } },
  { selector: "node.transition.enabled", style: { "underlay-color": "#1a7f37", "underlay-opacity": 0.18, "underlay-padding": 5 } },
  { selector: ".hidden-branch", style: { opacity: 0.55 } },
  { selector: "node.transition.hidden-branch", style: { "background-color": "#8c959f", "border-style": "dashed" } },
  { selector: "edge", style: {
      width: 1.5, "line-color": "#5b6570", "target-arrow-color": "#5b6570", "target-arrow-shape": "triangle",
      "arrow-scale": 0.9, "curve-style": "bezier", label: "data(label)", "font-size": 10, color: "#1d232b",
      "text-background-color": "#fff", "text-background-opacity": 1, "text-background-padding": 1 } },
  { selector: "edge.back", style: { "curve-style": "unbundled-bezier", "control-point-distances": "data(bend)",
                                    "control-point-weights": 0.5 } },
  { selector: "edge.inhibitor", style: { "target-arrow-shape": "circle", "target-arrow-fill": "hollow", "arrow-scale": 1.1 } },
  { selector: "edge.hidden-branch", style: { "line-style": "dashed", "line-color": "#8c959f", "target-arrow-color": "#8c959f" } },
  { selector: "node.badge", style: {
      width: 1, height: 1, "background-opacity": 0, "border-width": 0, label: "data(label)", "text-halign": "right",
      "text-valign": "center", "font-size": 10, color: "#7a3e00", "text-background-color": "#fff7e6",
      "text-background-opacity": 0.95, "text-background-padding": 3, "text-border-color": "#f0b35a",
      "text-border-width": 1, "text-border-opacity": 1, "text-wrap": "wrap", "text-max-width": 230, events: "no" } },
  { selector: "node.badge.latched", style: { color: "#0b4f8a", "text-background-color": "#eef6ff", "text-border-color": "#7fb0e0" } },
  { selector: "node.badge.failing", style: { color: "#a40e26", "text-background-color": "#fff0f0", "text-border-color": "#cf222e" } },
  { selector: "node.place.failing", style: { "border-color": "#cf222e", "underlay-color": "#cf222e", "underlay-opacity": 0.25,
                                             "underlay-padding": 8, "underlay-shape": "ellipse" } },
  { selector: "node.transition.failing", style: { "background-color": "#cf222e", "underlay-color": "#cf222e",
                                                  "underlay-opacity": 0.22, "underlay-padding": 6 } },
  { selector: ".problem", style: { "underlay-color": "#cf222e", "underlay-opacity": 0.28, "underlay-padding": 6 } },
  { selector: "edge.problem", style: { "line-color": "#cf222e", "target-arrow-color": "#cf222e" } },
  { selector: ":selected", style: { "overlay-color": "#1f6feb", "overlay-opacity": 0.18, "overlay-padding": 6 } },
  { selector: "node.arc-source", style: { "overlay-color": "#1a7f37", "overlay-opacity": 0.3, "overlay-padding": 8 } },
  { selector: "node.steerable", style: { "underlay-color": "#1f6feb", "underlay-opacity": 0.12, "underlay-padding": 8,
                                         "underlay-shape": "ellipse" } },
];

export class Graph {
  constructor(container) {
    if (window.cytoscapeElk && !Graph.elkRegistered) { cytoscape.use(window.cytoscapeElk); Graph.elkRegistered = true; }
    this.cy = cytoscape({ container, style: STYLE, minZoom: 0.05, maxZoom: 4,
                          boxSelectionEnabled: true, selectionType: "single", textureOnViewport: false,
                          pixelRatio: "auto" });
    this.showHidden = true;
    this.labelMode = "events";   // like the paper's Fig. 1: transitions named by their events
    this.tokens = new Map();      // place id -> shown count
    this.tokenLayer = new TokenLayer(this.cy, container);
    this.flashTimer = null;
    this.flashing = new Set();
    this.badges = new Map();      // place id -> text
    this.failing = { places: [], transitions: [] };  // a run's failing primitive tasks: places, error branches
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
      wanted.set(key, { group: "edges", data: { id: key, source: a.from, target: a.to, label: w !== 1 ? String(w) : "",
        kind: "arc", key: arcKey(a) }, classes: `${a.inhibitor ? "inhibitor" : ""}${hiddenOf(a) ? " hidden-branch" : ""}` });
    }
    cy.batch(() => {
      cy.elements().forEach((el) => {
        if (el.hasClass("badge")) return;
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
          el.classes(want.classes);
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
    if (fit) this.fit();
  }

  /** Arcs that climb a long way (back to an earlier stage: a resource returned, a run restarted)
   *  bow out towards the nearer side of the drawing instead of cutting through it. */
  bendBackArcs() {
    const cy = this.cy;
    const nodes = cy.nodes().not(".badge");
    if (!nodes.length || cy.edges().length > 3000) return;
    const bb = nodes.boundingBox();
    const mid = (bb.x1 + bb.x2) / 2;
    cy.edges().forEach((e) => {
      const a = e.source().position(), b = e.target().position();
      const rise = a.y - b.y;
      const length = Math.hypot(rise, b.x - a.x);
      if (rise < 160 || length < 1) { e.removeClass("back"); return; }
      // outward: the side of the line away from the middle of the drawing
      const outward = (a.x + b.x) / 2 >= mid ? 1 : -1;
      // cytoscape's distances are perpendicular to source -> target; a positive one bows a climbing
      // arc to the right on screen
      const sign = outward;
      e.data("bend", sign * Math.min(220, 0.25 * length));
      e.addClass("back");
    });
  }

  fit() { this.cy.fit(this.cy.elements(":visible").not(".badge"), 40); if (this.cy.zoom() > 1.6) { this.cy.zoom(1.6); this.cy.center(); } }

  applyHidden() {
    const show = this.showHidden;
    this.cy.elements(".hidden-branch").style("display", show ? "element" : "none");
    this.tokenLayer.refresh();
    this.cy.nodes(".badge").forEach((b) => {
      const place = this.cy.getElementById(b.data("place"));
      b.style("display", place.nonempty() && place.style("display") !== "none" ? "element" : "none");
    });
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
      this.tokenLayer.show(id, n);
    }
  }

  /** Flash the given transitions for a moment (coalesced: one timer). */
  flash(ids) {
    const cy = this.cy;
    const lit = ids.filter((id) => !this.flashing.has(id));  // the others are still lit from an earlier frame
    if (lit.length) {
      cy.batch(() => {
        for (const id of lit) {
          this.flashing.add(id);
          cy.getElementById(id).addClass("fired");
        }
      });
    }
    clearTimeout(this.flashTimer);
    this.flashTimer = setTimeout(() => {
      cy.batch(() => { for (const id of this.flashing) cy.getElementById(id).removeClass("fired"); });
      this.flashing.clear();
    }, 280);
  }

  /** Badges beside places: Map place id -> {text, latched}. */
  setBadges(map) {
    this.badges = map;
    this.refreshBadges();
  }

  refreshBadges() {
    const cy = this.cy;
    cy.batch(() => {
      cy.nodes(".badge").forEach((b) => { if (!this.badges.has(b.data("place"))) b.remove(); });
      cy.nodes(".place.busy").forEach((n) => {
        const badge = this.badges.get(n.id());
        if (!badge || badge.latched || badge.failing) n.removeClass("busy");
      });
      for (const [pid, badge] of this.badges) {
        const place = cy.getElementById(pid);
        if (place.empty()) continue;
        const id = "badge:" + pid;
        let b = cy.getElementById(id);
        const p = place.position();
        const at = { x: p.x + PLACE_D / 2 + 6, y: p.y - PLACE_D / 2 - 4 };
        if (b.empty()) b = cy.add({ group: "nodes", data: { id, place: pid, label: badge.text }, position: at,
                                    classes: "badge", selectable: false, grabbable: false, locked: true });
        else { b.data("label", badge.text); b.unlock(); b.position(at); b.lock(); }
        b.toggleClass("latched", !!badge.latched);
        b.toggleClass("failing", !!badge.failing);
        place.toggleClass("busy", !badge.latched && !badge.failing);
      }
      this.applyHidden();
    });
  }

  /** Mark the places of primitive tasks whose last results were errors, and their error branches. */
  setFailing(places, transitions) {
    this.failing = { places, transitions };
    this.cy.batch(() => this.applyFailing());
  }

  applyFailing() {
    const cy = this.cy;
    const want = new Set([...this.failing.places, ...this.failing.transitions]);
    cy.nodes(".failing").not(".badge").forEach((n) => { if (!want.has(n.id())) n.removeClass("failing"); });
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

  positions() {
    const out = {};
    this.cy.nodes().not(".badge").forEach((n) => { const p = n.position(); out[n.id()] = [Math.round(p.x * 10) / 10, Math.round(p.y * 10) / 10]; });
    return out;
  }

  /** Lay the drawing out with ELK (layered, top to bottom); resolves with the new positions. */
  tidy() {
    return new Promise((resolve) => {
      const eles = this.cy.elements().not(".badge");
      const layout = eles.layout({ name: "elk", fit: true, padding: 40, nodeDimensionsIncludeLabels: false,
        elk: { algorithm: "layered", "elk.direction": "DOWN", "elk.spacing.nodeNode": 50,
               "elk.layered.spacing.nodeNodeBetweenLayers": 55, "elk.layered.nodePlacement.strategy": "BRANDES_KOEPF",
               "elk.layered.cycleBreaking.strategy": "DEPTH_FIRST" } });
      layout.one("layoutstop", () => { this.refreshBadges(); resolve(this.positions()); });
      layout.run();
    });
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

/** Tokens as small HTML elements over cytoscape's canvas: one per marked place, placed in model
 *  coordinates on a plane that one CSS transform keeps on cytoscape's pan and zoom. */
class TokenLayer {
  constructor(cy, container) {
    this.cy = cy;
    this.layer = document.createElement("div");
    this.layer.className = "token-layer";
    this.plane = document.createElement("div");
    this.plane.className = "token-plane";
    this.layer.append(this.plane);
    container.after(this.layer);
    this.dots = new Map();   // place id -> element
    cy.on("viewport resize", () => this.follow());
    cy.on("position", "node.place", (ev) => this.place(ev.target.id()));
    cy.on("add remove data", "node.place", (ev) => this.place(ev.target.id()));
    cy.on("style", "node.place", (ev) => this.place(ev.target.id()));
    this.follow();
  }

  follow() {
    const pan = this.cy.pan(), zoom = this.cy.zoom();
    this.plane.style.transform = `translate(${pan.x}px, ${pan.y}px) scale(${zoom})`;
  }

  /** Show ``n`` tokens on place ``id`` (0: none). */
  show(id, n) {
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

  /** Put a place's tokens where the place is drawn (hidden with it, faded with it). */
  place(id) {
    const dot = this.dots.get(id);
    if (!dot) return;
    const node = this.cy.getElementById(id);
    if (node.empty() || node.removed() || node.style("display") === "none") { dot.style.display = "none"; return; }
    const p = node.position();
    dot.style.display = "";
    dot.style.transform = `translate(${p.x - 22}px, ${p.y - 22}px)`;
    dot.style.opacity = node.style("opacity");
  }

  refresh() { for (const id of this.dots.keys()) this.place(id); this.follow(); }
}

function pos(item) {
  const p = item.pos;
  if (Array.isArray(p) && p.length === 2 && Number.isFinite(p[0]) && Number.isFinite(p[1])) return { x: p[0], y: p[1] };
  return { x: 0, y: 0 };
}
