// The analyses on the drawing (paper section 2's three views of one net): `petrobot analyze`, `gspn`,
// `perf` and `learn` run on the server with --json, and the page draws the very JSON the commands
// give on the net — each place's bound, dead and non-live transitions, P- and T-invariants on click,
// deadlocks and other ends as markings reached by a firing sequence the operator plays like a replay,
// the GSPN view as a heat map with the bottleneck named, J / R / C beside each primitive task's place
// and the learners' probabilities as bars on it. Every number links to its definition in the docs.

import { el, fmt } from "./ui.js";

const KINDS = [
  ["analyze", "qualitative: bounds, liveness, deadlocks and their firing sequences, invariants"],
  ["gspn", "quantitative: the GSPN view as a heat map, the bottleneck (with the journal's measured times when the console has one)"],
  ["perf", "J = 1 \u2212 R + \u03c1C per primitive task, from the journal"],
  ["learn", "the learning automata's probabilities, from the journal"],
];

export function initAnalysis(app) {
  const panel = document.getElementById("panel-analysis");
  const state = { results: {}, drawn: null, trace: null, invariant: null, busy: null, text: null };
  app.analysis = state;

  function link(kind, text, title = "") {
    const href = app.doc(kind);
    return href ? el("a", { href, target: "_blank", rel: "noopener", title: title || "its definition in the docs" }, text) : el("span", { title }, text);
  }

  // ------------------------------------------------------------------ running
  async function run(kind, format = "json") {
    const draft = app.currentDraft();
    if (!draft) return;
    state.busy = kind;
    render();
    const runId = app.mode === "replay" && app.replay?.data ? app.replay.data.run.id : null;
    const reply = await app.link.request("analyze", { kind, draft, run: runId, format });
    state.busy = null;
    if (!reply.ok) { state.error = reply.reason; render(); return; }
    state.error = null;
    const r = reply.report;
    if (format === "text" || !r.data) {
      state.text = r;
    } else {
      state.results[kind] = { data: r.data, command: r.command, stderr: r.stderr, key: JSON.stringify(draft) };
      state.text = null;
    }
    redraw();
    render();
    document.body.dataset.analysed = kind;
  }
  app.runAnalysis = run;

  // ------------------------------------------------------------------ the panel
  function render() {
    panel.replaceChildren(el("h3", {}, "Analyses on the net"),
      el("p", { class: "small" }, "each runs the petrobot command of the same name on the net as drawn, in its own process, "
        + "and draws its JSON on the net; every number links to its definition"));
    const row = el("div", { class: "chips" });
    for (const [kind, what] of KINDS) {
      const b = el("button", { title: what, "data-kind": kind }, state.busy === kind ? `${kind}\u2026` : kind);
      b.disabled = !app.control || state.busy !== null;
      b.addEventListener("click", () => run(kind));
      row.append(b);
    }
    panel.append(row);
    if (!app.control) panel.append(el("p", { class: "small" }, "read-only: analyses need the console's token"));
    if (state.error) panel.append(el("p", { class: "node-bad" }, state.error));
    const stale = Object.entries(state.results).filter(([, r]) => r.key !== JSON.stringify(app.currentDraft()));
    if (stale.length) panel.append(el("p", { class: "small node-bad" }, "the net changed since: run the analyses again"));
    const q = state.results.analyze?.data;
    if (q) renderQualitative(q);
    const g = state.results.gspn?.data;
    if (g) renderGspn(g);
    const p = state.results.perf?.data;
    if (p) renderPerf(p);
    const l = state.results.learn?.data;
    if (l) renderLearn(l);
    if (Object.keys(state.results).length) {
      const clear = el("button", {}, "clear the drawing");
      clear.addEventListener("click", () => { clearAll(); render(); });
      panel.append(el("p", {}, clear));
    }
    if (state.text) {
      const r = state.text;
      panel.append(el("h4", {}, `${r.command} \u2014 exit ${r.exit === null ? "killed" : r.exit}`));
      if (r.stdout) panel.append(el("pre", { class: "report" }, r.stdout));
      if (r.stderr) panel.append(el("pre", { class: "report node-bad" }, r.stderr));
      if (r.plot) panel.append(el("img", { class: "plot", alt: `${r.kind} plot`, src: `data:image/png;base64,${r.plot}` }));
    }
    const texts = el("p", { class: "small" }, "the command line's text: ");
    for (const [kind] of KINDS) {
      const b = el("button", {}, kind);
      b.disabled = !app.control || state.busy !== null;
      b.addEventListener("click", () => run(kind, "text"));
      texts.append(b, " ");
    }
    panel.append(texts);
  }

  function yes(v) { return v === true ? "yes" : v === false ? "no" : "undecided"; }

  function renderQualitative(q) {
    // a stopped search's count is a lower bound: "at least", never the net's count
    const found = q.truncated ? `at least ${q.truncated.states_found}` : "?";
    panel.append(el("h4", {}, `petrobot analyze \u2014 ${q.states ?? found} markings`));
    const facts = el("ul", { class: "small" },
      el("li", {}, link("bound", "bounded"), `: ${yes(q.bounded)}; the bound of each place is drawn on it`),
      el("li", {}, link("liveness", "live"), `: ${yes(q.live)}; `,
        `${(q.dead_transitions || []).length} dead, ${Object.values(q.liveness || {}).filter((l) => l !== "L4").length} not live transitions marked`),
      el("li", {}, link("deadlock", "dead markings"), `: ${q.n_deadlocks ?? (q.deadlocks || []).length}`,
        q.ends ? ` (${q.ends.intended} intended ends, ${q.ends.operator} waiting for the operator, ${q.ends.stuck} stuck)` : ""),
      el("li", {}, "reversible: ", yes(q.reversible)));
    panel.append(facts);
    // markings to look at: the deadlocks the command gives, and its examples of each kind of end
    const picks = [];
    for (const d of q.deadlocks || []) picks.push({ kind: "dead marking", ...d });
    for (const [kind, list] of Object.entries(q.ends?.examples || {})) for (const d of list) picks.push({ kind: `${kind} end`, ...d });
    const seen = new Set();
    const unique = picks.filter((d) => { const k = JSON.stringify([d.marking, d.firing_sequence]); if (seen.has(k)) return false; seen.add(k); return true; });
    if (unique.length) {
      panel.append(el("p", { class: "subhead" }, link("deadlock", "Dead markings and ends"), " \u2014 click one to see it on the net, reached by its firing sequence"));
      const list = el("ul", { class: "analysis-list", id: "deadlock-list" });
      unique.slice(0, 40).forEach((d, i) => {
        const li = el("li", { class: state.trace?.index === i ? "current" : "", "data-index": String(i) },
          el("b", {}, d.kind), ` after ${d.firing_sequence.length} firing${d.firing_sequence.length === 1 ? "" : "s"}: `,
          el("span", { class: "mono" }, markingText(d.marking)));
        li.addEventListener("click", () => startTrace(d, i));
        list.append(li);
      });
      panel.append(list);
    }
    if (state.trace) panel.append(traceView());
    for (const [key, title] of [["p_invariants", "P-invariants"], ["t_invariants", "T-invariants"]]) {
      const invs = q[key] || [];
      panel.append(el("p", { class: "subhead" }, link("invariant", title), ` \u2014 ${invs.length}; click one to highlight it`));
      const list = el("ul", { class: "analysis-list", id: `${key.replace("_", "-")}-list` });
      invs.slice(0, 30).forEach((inv, i) => {
        const id = `${key}:${i}`;
        const li = el("li", { class: state.invariant === id ? "current" : "" }, el("span", { class: "mono" },
          Object.entries(inv).map(([n, w]) => (w === 1 ? n : `${w}\u00b7${n}`)).join(" + ")));
        li.addEventListener("click", () => { state.invariant = state.invariant === id ? null : id; state.invariantSet = inv; redraw(); render(); });
        list.append(li);
      });
      panel.append(list);
    }
  }

  function renderGspn(g) {
    panel.append(el("h4", {}, "petrobot gspn \u2014 heat map"));
    const b = (g.bottlenecks || [])[0];
    panel.append(el("ul", { class: "small" },
      el("li", {}, `${g.tangible_markings} tangible markings; `, ...(g.terminates
        ? ["the task ends: mean time to the end ", link("measures", `${fmt(g.mean_time_to_absorption)} s`)]
        : ["steady state"])),
      el("li", {}, link("measures", g.terminates ? "heat: expected firings of each transition, share of the time each task runs"
        : "heat: utilisation of each place (P(marked)), throughput of each transition (1/s)")),
      b ? el("li", {}, el("b", {}, "bottleneck: "), `${nodeOf(b.transition)} `, link("measures", `(${Math.round((b.share || 0) * 100)}% of the time, ${b.criterion})`))
        : el("li", {}, "no bottleneck named")));
    panel.append(el("div", { class: "heat-legend" }, "low", el("i", { class: "ramp" }), "high"));
    for (const w of g.warnings || []) panel.append(el("p", { class: "small" }, `warning: ${w}`));
  }

  function renderPerf(p) {
    panel.append(el("h4", {}, `petrobot perf \u2014 ${p.results} results`));
    panel.append(el("p", { class: "small" }, link("j", "J = 1 \u2212 R + \u03c1C"), ", lower is better; drawn beside each primitive task's place"
      + (p.forced_left_out ? `; ${p.forced_left_out} outcome(s) forced by the operator left out` : "")));
  }

  function renderLearn(l) {
    panel.append(el("h4", {}, "petrobot learn"));
    panel.append(el("p", { class: "small" }, link("learner", "probability of choosing each action next"), " drawn as bars on each task's place"));
    for (const [task, t] of Object.entries(l.tasks || {})) {
      panel.append(el("p", { class: "small" }, el("b", {}, task), ` ${t.scheme}, ${t.steps} results${t.converged ? `, converged to ${t.converged}` : ""}`));
    }
  }

  function markingText(m) { return Object.entries(m || {}).map(([p, n]) => (n === 1 ? p : `${p}\u00d7${n}`)).join(", ") || "empty"; }

  /** A GSPN transition of the P-timed view (``locating.run``) is the place of its task on the drawing. */
  function nodeOf(tid) { return tid && tid.endsWith(".run") ? tid.slice(0, -4) : tid; }

  // ------------------------------------------------------------------ a marking reached by a firing sequence, played on the net
  function startTrace(d, index) {
    const draft = app.currentDraft();
    const steps = markings(draft, d.firing_sequence);
    state.trace = { ...d, index, steps, k: steps.length - 1, playing: false };
    const last = steps[steps.length - 1];
    state.trace.agrees = sameMarking(last, d.marking);
    showTrace();
    render();
  }

  function markings(draft, sequence) {
    const m = {};
    for (const p of draft.places) if (Number.isInteger(p.tokens) && p.tokens > 0) m[p.id] = p.tokens;
    const ins = new Map(), outs = new Map(), resets = new Map();
    for (const a of draft.arcs) {
      if (a.inhibitor) continue;
      const table = a.reset ? resets : draft.transitions.some((t) => t.id === a.to) ? ins : outs;
      const key = table === outs ? a.from : a.to;
      if (!table.has(key)) table.set(key, []);
      table.get(key).push(a);
    }
    const out = [{ marking: { ...m }, fired: null }];
    for (const t of sequence) {
      if (t.startsWith("operator_adds_to.")) {
        const p = t.slice("operator_adds_to.".length);
        m[p] = (m[p] || 0) + 1;
      } else {
        for (const a of ins.get(t) || []) m[a.from] = (m[a.from] || 0) - (a.weight ?? 1);
        for (const a of resets.get(t) || []) m[a.from] = 0;
        for (const a of outs.get(t) || []) m[a.to] = (m[a.to] || 0) + (a.weight ?? 1);
      }
      for (const p of Object.keys(m)) if (!m[p]) delete m[p];
      out.push({ marking: { ...m }, fired: t });
    }
    return out;
  }

  function sameMarking(a, b) {
    const ka = Object.keys(a.marking).filter((p) => a.marking[p]), kb = Object.keys(b || {}).filter((p) => b[p]);
    return ka.length === kb.length && ka.every((p) => a.marking[p] === b[p]);
  }

  function showTrace() {
    const t = state.trace;
    if (!t) return;
    const step = t.steps[t.k];
    app.graph.setMarking(step.marking, true);
    if (step.fired) app.graph.flash([nodeOf(step.fired)]);
    const marks = [];
    if (step.fired && app.graph.cy.getElementById(step.fired).nonempty()) {
      marks.push({ key: "trace:step", node: step.fired, at: "left", cls: "trace-step", text: `${t.k}/${t.steps.length - 1}`,
                   title: `firing ${t.k} of the sequence reaching this ${t.kind}` });
    }
    app.graph.setMarks("trace", marks);
    document.body.dataset.traceStep = String(t.k);
    const box = document.getElementById("trace-steps");
    if (box) {
      box.querySelectorAll("div").forEach((d, i) => d.classList.toggle("here", i === t.k));
      box.querySelector("div.here")?.scrollIntoView({ block: "nearest" });
      document.getElementById("trace-pos").textContent = `${t.k} / ${t.steps.length - 1}`;
    }
  }

  function seekTrace(k) {
    const t = state.trace;
    if (!t) return;
    t.k = Math.max(0, Math.min(k, t.steps.length - 1));
    showTrace();
  }
  app.traceSeek = seekTrace;

  function traceView() {
    const t = state.trace;
    const box = el("div", { class: "trace" },
      el("b", {}, `${t.kind}: `), el("span", { class: "mono" }, markingText(t.marking)),
      t.agrees ? "" : el("p", { class: "small node-bad" }, "the sequence played on the drawing does not end in this marking (the drawing changed?)"));
    const steps = el("div", { class: "steps", id: "trace-steps" });
    t.steps.forEach((s, i) => {
      const row = el("div", { class: i === t.k ? "here" : "" }, i === 0 ? "0 initial marking" : `${i} ${s.fired}`);
      row.addEventListener("click", () => { stopTrace(); seekTrace(i); });
      steps.append(row);
    });
    const b = (text, title, fn) => { const x = el("button", { title }, text); x.addEventListener("click", fn); return x; };
    const controls = el("div", { class: "controls" },
      b("|\u25C0", "the initial marking", () => { stopTrace(); seekTrace(0); }),
      b("\u25C0", "one firing back", () => { stopTrace(); seekTrace(t.k - 1); }),
      b(t.playing ? "\u2016" : "\u25B6", "play the sequence", () => (t.playing ? stopTrace() : playTrace())),
      b("\u25B6\u25B6", "one firing on", () => { stopTrace(); seekTrace(t.k + 1); }),
      b("\u25B6|", "the marking reached", () => { stopTrace(); seekTrace(t.steps.length - 1); }),
      el("span", { id: "trace-pos", class: "small" }, `${t.k} / ${t.steps.length - 1}`),
      b("close", "back to the net's initial marking", () => { stopTrace(); state.trace = null; app.graph.setMarks("trace", []); app.redraw(); render(); }));
    box.append(controls, steps);
    return box;
  }

  function playTrace() {
    const t = state.trace;
    if (!t) return;
    if (t.k >= t.steps.length - 1) seekTrace(0);
    t.playing = true;
    render();
    const tick = () => {
      if (!state.trace || !state.trace.playing) return;
      if (state.trace.k >= state.trace.steps.length - 1) { stopTrace(); return; }
      seekTrace(state.trace.k + 1);
      state.trace.timer = setTimeout(tick, 600);
    };
    t.timer = setTimeout(tick, 300);
  }
  function stopTrace() {
    const t = state.trace;
    if (!t) return;
    clearTimeout(t.timer);
    if (t.playing) { t.playing = false; render(); }
  }

  // ------------------------------------------------------------------ the drawing
  function heatColour(x) {
    const v = Math.max(0, Math.min(1, x));
    const r = 255, g = Math.round(243 - v * 210), b = Math.round(196 - v * 196);
    return v > 0.85 ? "#cf222e" : `rgb(${r},${g},${b})`;
  }

  function clearAll() {
    state.results = {};
    state.trace = null;
    state.invariant = null;
    redraw();
  }

  /** Draw the analyses' results on the net (classes on cytoscape's elements, marks on the plane). */
  function redraw() {
    const cy = app.graph.cy;
    const draft = app.currentDraft();
    if (!draft) return;
    const key = JSON.stringify(draft);
    const fresh = (k) => state.results[k] && state.results[k].key === key ? state.results[k].data : null;
    const q = fresh("analyze"), g = fresh("gspn"), p = fresh("perf"), l = fresh("learn");
    const marks = [];
    cy.batch(() => {
      cy.nodes(".heat, .bottleneck, .dead, .notlive, .inv").removeClass("heat bottleneck dead notlive inv");
      if (q) {
        for (const [place, bound] of Object.entries(q.place_bounds || {})) {
          if (cy.getElementById(place).empty()) continue;
          const unbounded = bound === null || bound === "unbounded" || (q.unbounded_places || []).includes(place);
          marks.push({ key: `bound:${place}`, node: place, at: "above", cls: unbounded ? "unbounded" : "bound",
                       text: unbounded ? "\u221e" : `\u2264${bound}`, href: app.doc("bound"),
                       title: unbounded ? `${place} is unbounded` : `bound of ${place}: at most ${bound} tokens in any reachable marking (${q.sources?.place_bounds || "petrobot analyze"})` });
        }
        const dead = new Set(q.dead_transitions || []);
        for (const [t, level] of Object.entries(q.liveness || {})) {
          const node = cy.getElementById(t);
          if (node.empty() || level === "L4") continue;
          const isDead = dead.has(t) || level === "L0";
          node.addClass(isDead ? "dead" : "notlive");
          marks.push({ key: `live:${t}`, node: t, at: "left", cls: isDead ? "dead" : "live", text: isDead ? "dead" : level,
                       href: app.doc("liveness"), title: isDead ? `${t} can never fire (L0)` : `${t} is ${level}, not live (L4)` });
        }
        if (state.invariant && state.invariantSet) {
          for (const [n, w] of Object.entries(state.invariantSet)) {
            const node = cy.getElementById(n);
            if (node.empty()) continue;
            node.addClass("inv");
            if (w !== 1) marks.push({ key: `inv:${n}`, node: n, at: "below-left", cls: "inv", text: `\u00d7${w}`, href: app.doc("invariant"),
                                      title: `weight of ${n} in the invariant` });
          }
        }
      }
      if (g) {
        const places = draft.places.map((x) => x.id);
        if (g.terminates) {
          const te = g.time_enabled || {}, total = g.mean_time_to_absorption || 1;
          for (const pl of places) {
            const share = te[`${pl}.run`];
            if (share === undefined) continue;
            setHeat(pl, share / total);
            marks.push({ key: `heat:${pl}`, node: pl, at: "below-left", cls: "heat", text: `${Math.round(share / total * 100)}%`,
                         href: app.doc("measures"), title: `${pl}: its task runs ${fmt(share)} s of the ${fmt(total)} s the task takes on average` });
          }
          const ef = g.expected_firings || {};
          const max = Math.max(1e-12, ...draft.transitions.map((t) => ef[t.id] || 0));
          for (const t of draft.transitions) {
            if (ef[t.id] === undefined) continue;
            setHeat(t.id, ef[t.id] / max);
            marks.push({ key: `heat:${t.id}`, node: t.id, at: "left", cls: "heat", text: `n=${fmt(ef[t.id], 2)}`, href: app.doc("measures"),
                         title: `${t.id}: fires ${fmt(ef[t.id])} times on average before the task ends` });
          }
        } else {
          const pn = g.probability_nonempty || {};
          for (const pl of places) {
            if (pn[pl] === undefined) continue;
            setHeat(pl, pn[pl]);
            marks.push({ key: `heat:${pl}`, node: pl, at: "below-left", cls: "heat", text: `U=${fmt(pn[pl], 2)}`, href: app.doc("measures"),
                         title: `utilisation of ${pl}: the probability that it holds a token (steady state)` });
          }
          const th = g.throughput || {};
          const max = Math.max(1e-12, ...draft.transitions.map((t) => th[t.id] || 0));
          for (const t of draft.transitions) {
            if (th[t.id] === undefined) continue;
            setHeat(t.id, th[t.id] / max);
            marks.push({ key: `heat:${t.id}`, node: t.id, at: "left", cls: "heat", text: `${fmt(th[t.id], 2)}/s`, href: app.doc("measures"),
                         title: `throughput of ${t.id}: firings per second (steady state)` });
          }
        }
        const b = (g.bottlenecks || [])[0];
        const node = b && cy.getElementById(nodeOf(b.transition));
        if (node && node.nonempty()) {
          node.addClass("bottleneck");
          marks.push({ key: "bottleneck", node: node.id(), at: "right", cls: "bottleneck", text: "bottleneck", href: app.doc("measures"),
                       title: `${b.transition}: ${Math.round((b.share || 0) * 100)}% (${b.criterion})` });
        }
      }
    });
    function setHeat(id, x) {
      const node = cy.getElementById(id);
      if (node.empty() || !(x > 0)) return;
      node.data("heat", heatColour(x));
      node.addClass("heat");
    }
    // J / R / C beside each primitive task's place (perf); the learners' probabilities as bars (learn, or the live run)
    const taskPlaces = new Map();
    for (const pl of draft.places) if (pl.task) { if (!taskPlaces.has(pl.task)) taskPlaces.set(pl.task, []); taskPlaces.get(pl.task).push(pl.id); }
    if (p) {
      for (const [task, entry] of Object.entries(p.primitive_tasks || {})) {
        const row = entry.used_mix || entry.best;
        for (const pl of taskPlaces.get(task) || []) {
          marks.push({ key: `jrc:${pl}`, node: pl, at: "right", cls: "jrc",
                       text: `J ${fmt(row.j, 2)} \u00b7 R ${fmt(row.reliability, 2)} \u00b7 C ${fmt(row.cost, 2)}`, href: app.doc("j"),
                       title: `${task}: J = 1 \u2212 R + \u03c1C = ${fmt(row.j)} (lower is better), R = ${fmt(row.reliability)}, C = ${fmt(row.cost)}, \u03c1 = ${fmt(row.rho)}; ${row.basis}` });
        }
      }
    }
    const learners = {};
    if (l) for (const [task, t] of Object.entries(l.tasks || {})) learners[task] = Object.entries(t.actions || {}).map(([name, a]) => [name, a.probability]);
    if (app.mode === "live" && app.live) {
      for (const [task, v] of Object.entries(app.live.learner || {})) learners[task] = (v.actions || []).map((a) => [a.name, a.p]);
    }
    for (const [task, rows] of Object.entries(learners)) {
      if (rows.length < 2) continue;  // one action: nothing to choose
      for (const pl of taskPlaces.get(task) || []) {
        marks.push({ key: `learner:${pl}`, node: pl, at: p ? "below-left" : "right", cls: "learner", href: app.doc("learner"), bars: rows,
                     text: rows.map(([n, pr]) => `${n} ${fmt(pr, 2)}`).join("\n"),
                     title: `${task}: probability of choosing each action next (learning automaton, section 4)` });
      }
    }
    app.graph.setMarks("analysis", marks);
  }

  return {
    render, redraw,
    clear() { stopTrace(); state.trace = null; state.invariant = null; app.graph.setMarks("trace", []); },
  };
}
