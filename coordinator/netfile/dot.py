"""Graphviz DOT pictures of a net (pure: returns text, draws nothing).

Conventions (after the usual Petri-net drawings and the GSPN ones of Ajmone Marsan et al.,
*Modelling with Generalized Stochastic Petri Nets*, 1995):

* places are circles holding their token count, named beside them (``xlabel``); the fill colour
  gives the kind: resource blue, primitive task yellow (double circle, task name shown), control
  grey with a bold outline, plain white;
* transitions are boxes showing the id (or label), the linked events and a non-zero priority;
  immediate transitions are filled, exponential ones are white and show their rate (1/s);
* error-recovery branches (``hidden`` transitions, paper section 2) are dashed and grey, or left
  out with ``show_hidden=False`` together with the places that only they touch;
* inhibitor arcs end in a hollow circle (``arrowhead=odot``); reset arcs are dashed with a double
  arrowhead (``arrowhead=normalnormal``) and labelled ``reset``; arc weights other than 1 label the arc;
* a marking-dependent rate or weight is shown as its expression.

Render with ``dot -Tsvg net.dot -o net.svg`` (Graphviz is not a dependency of petrobot).
"""

from __future__ import annotations

from collections.abc import Mapping

from coordinator.net import PetriNet, Place, PlaceKind, Transition, TransitionKind

__all__ = ["PLACE_STYLE", "to_dot"]

#: Graphviz attributes of a place per kind.
PLACE_STYLE: Mapping[PlaceKind, Mapping[str, str]] = {
    PlaceKind.RESOURCE: {"shape": "circle", "style": "filled", "fillcolor": "#cfe2ff"},
    PlaceKind.PRIMITIVE_TASK: {"shape": "doublecircle", "style": "filled", "fillcolor": "#fff3bf"},
    PlaceKind.CONTROL: {"shape": "circle", "style": "filled", "fillcolor": "#e9ecef", "penwidth": "2"},
    PlaceKind.PLAIN: {"shape": "circle", "style": "filled", "fillcolor": "white"},
}


def _q(text: str) -> str:
    """Quote a DOT id or label (``\\n`` in ``text`` stays a DOT line break)."""
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'


def _attrs(attrs: Mapping[str, str]) -> str:
    return "[" + ", ".join(f"{k}={_q(v)}" for k, v in attrs.items()) + "]"


def _place_node(place: Place, tokens: int) -> str:
    attrs = dict(PLACE_STYLE[place.kind])
    attrs["label"] = str(tokens) if tokens else ""
    name = place.label or place.id
    attrs["xlabel"] = f"{name}\n({place.task})" if place.task else name
    attrs["width"] = attrs["height"] = "0.5"
    attrs["fixedsize"] = "true"
    attrs["tooltip"] = f"place {place.id} ({place.kind.value})"
    return f"  {_q('p:' + place.id)} {_attrs(attrs)};"


def _transition_node(t: Transition) -> str:
    lines = [t.label or t.id, *t.events]
    if t.priority:
        lines.append(f"priority {t.priority}")
    if t.weight_expr is not None:
        lines.append(f"weight {t.weight_expr}")
    elif t.weight != 1.0:
        lines.append(f"weight {t.weight:g}")
    attrs = {"shape": "box", "label": "\n".join(lines), "tooltip": f"transition {t.id}"}
    if t.kind is TransitionKind.EXPONENTIAL:
        servers = "inf" if t.servers is None else str(t.servers)
        if t.rate_expr is not None:
            attrs["label"] += f"\nrate {t.rate_expr} /s"
        else:
            attrs["label"] += f"\nrate {t.rate:g}/s" + ("" if t.servers == 1 else f", {servers} servers")
        attrs["style"] = "solid"
    else:
        attrs["style"] = "filled"
        attrs["fillcolor"] = "#343a40"
        attrs["fontcolor"] = "white"
    if t.hidden:
        attrs["style"] = attrs["style"] + ",dashed"
        attrs["color"] = "gray50"
        if t.kind is TransitionKind.IMMEDIATE:
            attrs["fillcolor"] = "gray70"
    return f"  {_q('t:' + t.id)} {_attrs(attrs)};"


def to_dot(net: PetriNet, marking: Mapping[str, int] | None = None, show_hidden: bool = True) -> str:
    """Draw a net as a Graphviz digraph.

    Args:
        net: the net.
        marking: tokens to show, place id → count; the initial marking when ``None``.
        show_hidden: draw hidden (error-recovery) transitions dashed; ``False`` leaves them out, with
            their arcs and the places no visible transition touches.

    Returns:
        DOT source text (node names ``p:<id>`` for places and ``t:<id>`` for transitions).
    """
    tokens = net.initial_marking if marking is None else marking
    visible_t = [t for t in net.transitions if show_hidden or not t.hidden]
    visible_ids = {t.id for t in visible_t}
    hidden_ids = {t.id for t in net.transitions if t.hidden}
    touched: set[str] = set()
    for arc in net.arcs:
        for end, other in ((arc.source, arc.target), (arc.target, arc.source)):
            if end in visible_ids:
                touched.add(other)
    isolated = {p.id for p in net.places} - {a.source for a in net.arcs} - {a.target for a in net.arcs}
    places = [p for p in net.places if show_hidden or p.id in touched or p.id in isolated]
    shown_places = {p.id for p in places}

    out = [f"digraph {_q(net.name)} {{",
           f"  graph [rankdir=LR, label={_q(net.name)}, labelloc=t, fontname=Helvetica, forcelabels=true];",
           "  node [fontname=Helvetica, fontsize=10];",
           "  edge [fontname=Helvetica, fontsize=9];"]
    out += [_place_node(p, int(tokens.get(p.id, 0))) for p in places]
    out += [_transition_node(t) for t in visible_t]
    for arc in net.arcs:
        tid = arc.target if arc.source in net.place_index else arc.source
        pid = arc.source if tid == arc.target else arc.target
        if tid not in visible_ids or pid not in shown_places:
            continue
        src = ("p:" if arc.source == pid else "t:") + arc.source
        dst = ("p:" if arc.target == pid else "t:") + arc.target
        attrs: dict[str, str] = {}
        if arc.weight != 1:
            attrs["label"] = str(arc.weight)
        if arc.inhibitor:
            attrs["arrowhead"] = "odot"
        if arc.reset:
            attrs["arrowhead"] = "normalnormal"
            attrs["style"] = "dashed"
            attrs["label"] = "reset"
        if tid in hidden_ids:
            attrs["style"] = "dashed"
            attrs["color"] = "gray50"
        out.append(f"  {_q(src)} -> {_q(dst)}" + (f" {_attrs(attrs)}" if attrs else "") + ";")
    out.append("}")
    return "\n".join(out) + "\n"
