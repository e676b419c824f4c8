"""Small GSPNs with closed-form answers, shared by the GSPN, simulator and ptimed tests."""

from __future__ import annotations

from dataclasses import replace

from coordinator.net import Arc, PetriNet, Place, Transition, TransitionKind
from coordinator.netfile.pnml import load_pnml

EXP = TransitionKind.EXPONENTIAL


def exp(tid: str, rate: float, servers: int | None = 1) -> Transition:
    return Transition(id=tid, kind=EXP, rate=rate, servers=servers)


def imm(tid: str, weight: float = 1.0, priority: int = 0) -> Transition:
    return Transition(id=tid, weight=weight, priority=priority)


def arcs(*spec: tuple[str, str] | tuple[str, str, int]) -> list[Arc]:
    return [Arc(source=s[0], target=s[1], weight=s[2] if len(s) > 2 else 1) for s in spec]  # type: ignore[misc]


def queue(lam: float, mu: float, k: int, servers: int | None = 1) -> PetriNet:
    """M/M/c/K: ``arrive`` moves a slot from ``free`` to ``queue``; ``serve`` has c servers."""
    return PetriNet(
        name="mmck", places=[Place(id="queue"), Place(id="free")],
        transitions=[exp("arrive", lam), exp("serve", mu, servers)],
        arcs=arcs(("free", "arrive"), ("arrive", "queue"), ("queue", "serve"), ("serve", "free")),
        initial_marking={"free": k},
    )


def repairman(n: int, lam: float, mu: float) -> PetriNet:
    """Machine-repairman birth–death chain: n machines fail at rate lam each (infinite server),
    one repairman repairs at rate mu."""
    return PetriNet(
        name="repair", places=[Place(id="up"), Place(id="down")],
        transitions=[exp("fail", lam, None), exp("repair", mu)],
        arcs=arcs(("up", "fail"), ("fail", "down"), ("down", "repair"), ("repair", "up")),
        initial_marking={"up": n},
    )


def fork_join(a: float, b: float, r: float) -> PetriNet:
    """Fork two exponential activities, join, then a random switch ok (weight r) / fail (1 - r)."""
    return PetriNet(
        name="forkjoin",
        places=[Place(id=p) for p in ("start", "a", "b", "a_done", "b_done", "joined", "ok", "failed")],
        transitions=[imm("fork"), exp("ta", a), exp("tb", b), imm("join"), imm("succeed", r), imm("fail", 1 - r)],
        arcs=arcs(("start", "fork"), ("fork", "a"), ("fork", "b"), ("a", "ta"), ("ta", "a_done"),
                  ("b", "tb"), ("tb", "b_done"), ("a_done", "join"), ("b_done", "join"), ("join", "joined"),
                  ("joined", "succeed"), ("succeed", "ok"), ("joined", "fail"), ("fail", "failed")),
        initial_marking={"start": 1},
    )


def vanishing_loop(lam: float, mu: float, trap: bool = False) -> PetriNet:
    """``go`` (exp lam) moves S to A; A -> B -> A is a loop of immediate transitions left to S
    (weight 1) or T (weight 3) from B, back-edge weight 1; T returns to S at rate mu.
    With ``trap`` the loop has no exit."""
    transitions = [exp("go", lam), imm("a2b"), imm("b2a"), exp("back", mu)]
    spec = [("S", "go"), ("go", "A"), ("A", "a2b"), ("a2b", "B"), ("B", "b2a"), ("b2a", "A"),
            ("T", "back"), ("back", "S")]
    if not trap:
        transitions += [imm("b2s", 1.0), imm("b2t", 3.0)]
        spec += [("B", "b2s"), ("b2s", "S"), ("B", "b2t"), ("b2t", "T")]
    return PetriNet(
        name="vloop", places=[Place(id=p) for p in ("S", "A", "B", "T")], transitions=transitions,
        arcs=arcs(*spec), initial_marking={"S": 1},
    )


from tests.unit.mcc_models import MCC

#: Immediate transitions of the FMS GSPN of G. Ciardo and K. S. Trivedi ("A decomposition approach
#: for stochastic reward net models", Performance Evaluation 18, 1993): machine grabs, the join of
#: P1 and P2 parts, and the choice between finishing and joining after machining.
FMS_IMMEDIATE = frozenset({"tM1", "tM2", "tM3", "tx", "tP1e", "tP1j", "tP2e", "tP2j"})


def literature_net(model: str, n: int, immediate: frozenset[str] = frozenset()) -> PetriNet:
    """A Model Checking Contest PNML model with N parts per pallet place and GSPN attributes:
    transitions in ``immediate`` are immediate (weight 1), the others exponential of rate 1/s.

    ``model`` is ``"Kanban-PT-00005"`` (every place holding tokens gets N) or ``"FMS-PT-00002"``
    (P1, P2, P3 get N; the machines keep M1 = 3, M2 = 1, M3 = 2)."""
    base = load_pnml(MCC / model / "model.pnml")
    scaled = {p: (n if (model.startswith("Kanban") or p in ("P1", "P2", "P3")) else c)
              for p, c in base.initial_marking.items()}
    transitions = tuple(t if t.id in immediate else replace(t, kind=EXP, rate=1.0) for t in base.transitions)
    return PetriNet(name=f"{model}-{n}", places=base.places, transitions=transitions, arcs=base.arcs,
                    initial_marking=scaled)
