// The drawn net: the draft (the net file's tables as JSON, arcs apart) and its undo history.
// Shape (docs/console.md): {net:{name,...}, places:[{id,kind,tokens,pos,...}], tasks:{name:{actions,...}},
// transitions:[{id,events,pos,...}], arcs:[{from,to,weight,inhibitor}]}

export function emptyDraft(name = "untitled") {
  return { net: { name }, places: [], transitions: [], arcs: [], tasks: {} };
}

export function clone(draft) { return JSON.parse(JSON.stringify(draft)); }

export function findNode(draft, id) {
  const p = draft.places.find((x) => x.id === id);
  if (p) return { kind: "place", item: p };
  const t = draft.transitions.find((x) => x.id === id);
  if (t) return { kind: "transition", item: t };
  return null;
}

export function arcKey(a) { return `${a.from}->${a.to}${a.inhibitor ? "|inh" : a.reset ? "|reset" : ""}`; }

/** The kind of an arc: "normal", "inhibitor" or "reset". */
export function arcKind(a) { return a.inhibitor ? "inhibitor" : a.reset ? "reset" : "normal"; }

export function findArc(draft, key) { return draft.arcs.find((a) => arcKey(a) === key) || null; }

/** A fresh id: prefix followed by the first free number. */
export function freshId(draft, prefix) {
  const taken = new Set([...draft.places.map((p) => p.id), ...draft.transitions.map((t) => t.id)]);
  for (let i = 1; ; i++) if (!taken.has(`${prefix}${i}`)) return `${prefix}${i}`;
}

export const ID_RE = /^[A-Za-z_][A-Za-z0-9_.\-]*$/;
export const NAME_RE = /^[A-Za-z_][A-Za-z0-9_]*$/;

/** Rename a place or transition everywhere (arcs, home marking). Returns an error text or null. */
export function renameNode(draft, oldId, newId) {
  if (oldId === newId) return null;
  if (!ID_RE.test(newId)) return `bad id ${JSON.stringify(newId)}: use letters, digits, '_', '.', '-', starting with a letter or '_'`;
  if (findNode(draft, newId)) return `id ${newId} is taken`;
  const node = findNode(draft, oldId);
  if (!node) return `no element ${oldId}`;
  node.item.id = newId;
  for (const a of draft.arcs) {
    if (a.from === oldId) a.from = newId;
    if (a.to === oldId) a.to = newId;
  }
  const home = draft.net.home;
  if (home && oldId in home) { home[newId] = home[oldId]; delete home[oldId]; }
  return null;
}

/** Delete places/transitions (with their arcs) and arcs given by key. */
export function deleteElements(draft, nodeIds, arcKeys) {
  const ids = new Set(nodeIds);
  const keys = new Set(arcKeys);
  draft.places = draft.places.filter((p) => !ids.has(p.id));
  draft.transitions = draft.transitions.filter((t) => !ids.has(t.id));
  draft.arcs = draft.arcs.filter((a) => !ids.has(a.from) && !ids.has(a.to) && !keys.has(arcKey(a)));
  if (draft.net.home) for (const id of ids) delete draft.net.home[id];
}

/** Add an arc of ``kind`` ("normal", "inhibitor" or "reset"; ``true`` means inhibitor); returns an
 *  error text or null. Drawing a normal or inhibitor arc again adds one to its weight. */
export function addArc(draft, from, to, kind = "normal") {
  if (kind === true) kind = "inhibitor";
  if (kind === false) kind = "normal";
  const a = findNode(draft, from), b = findNode(draft, to);
  if (!a || !b) return "click two elements";
  if (from === to) return "an arc joins two elements";
  if (a.kind === b.kind) return "arcs join a place and a transition";
  if (kind !== "normal" && a.kind !== "place") return `a${kind === "inhibitor" ? "n inhibitor" : " reset"} arc goes from a place to a transition`;
  const arc = { from, to };
  if (kind !== "reset") arc.weight = 1;
  if (kind === "inhibitor") arc.inhibitor = true;
  if (kind === "reset") arc.reset = true;
  const existing = findArc(draft, arcKey(arc));
  if (existing) {
    if (kind === "reset") return `the reset arc ${from} -> ${to} is there already`;
    existing.weight = (existing.weight || 1) + 1;
    return null;
  }
  draft.arcs.push(arc);
  return null;
}

/** Task names used by primitive-task places, and defined. */
export function taskNames(draft) { return Object.keys(draft.tasks || {}); }

/** Undo/redo of whole drafts (snapshots as JSON text). */
export class History {
  constructor(limit = 200) { this.limit = limit; this.undos = []; this.redos = []; }
  record(draft) {
    this.undos.push(JSON.stringify(draft));
    if (this.undos.length > this.limit) this.undos.shift();
    this.redos = [];
  }
  undo(current) {
    if (!this.undos.length) return null;
    this.redos.push(JSON.stringify(current));
    return JSON.parse(this.undos.pop());
  }
  redo(current) {
    if (!this.redos.length) return null;
    this.undos.push(JSON.stringify(current));
    return JSON.parse(this.redos.pop());
  }
  clear() { this.undos = []; this.redos = []; }
  get canUndo() { return this.undos.length > 0; }
  get canRedo() { return this.redos.length > 0; }
}

/** The events of a transition split into parts: {kind:'int'|'ext', task, outcome, topic}. */
export function parseEvent(e) {
  let m = /^int:([A-Za-z_][A-Za-z0-9_]*)\.([A-Za-z_][A-Za-z0-9_]*)$/.exec(e);
  if (m) return { kind: "int", task: m[1], outcome: m[2] };
  m = /^ext:([A-Za-z_][A-Za-z0-9_]*)$/.exec(e);
  if (m) return { kind: "ext", topic: m[1] };
  return null;
}

/** Ids of the hidden transitions, their arcs, and the places only they touch. */
export function hiddenSet(draft) {
  const hidden = new Set(draft.transitions.filter((t) => t.hidden === true).map((t) => t.id));
  const touchedByVisible = new Set();
  const touchedByHidden = new Set();
  for (const a of draft.arcs) {
    const t = hidden.has(a.from) || hidden.has(a.to);
    const place = findNode(draft, a.from)?.kind === "place" ? a.from : a.to;
    (t ? touchedByHidden : touchedByVisible).add(place);
  }
  const places = [...touchedByHidden].filter((p) => !touchedByVisible.has(p));
  return { transitions: hidden, places: new Set(places) };
}
