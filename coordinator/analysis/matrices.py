"""Sparse incidence matrices of a net, built from its arc list (pure, no I/O).

:class:`coordinator.net.PetriNet` offers dense ``(|P|, |T|)`` int64 matrices (``pre``, ``post``,
``inhibitor``, ``incidence``). They are the right tool for task nets of tens of places, but a net
of 20,000 places and 20,000 transitions needs 3.2 GB for each of them, although it has only
40,000 arcs. The analyses of this package read the matrices through :func:`sparse_net`, which builds
compressed sparse column (CSC) matrices straight from the net's adjacency (O(arcs) time and memory)
and keeps them on the net object, as the net keeps its own dense matrices.

:func:`dense_is_cheap` says when the dense matrices are small enough (or already built) to use them
instead; the state-space search uses them then, because building them is cheaper for a small net.

Reference for the matrices themselves: Murata (1989), *Petri nets: properties, analysis and
applications*, section II (incidence matrix and state equation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from coordinator.net import PetriNet

__all__ = ["DENSE_LIMIT", "SparseNet", "dense_is_cheap", "sparse_net"]

#: largest |P|·|T| for which the dense matrices of a net are built on purpose (2 MB per matrix)
DENSE_LIMIT = 250_000
_CACHE_KEY = "_petrobot_sparse_net"


@dataclass(frozen=True, eq=False)
class SparseNet:
    """The matrices of a net in compressed sparse column form (columns = transitions).

    Attributes:
        n_places, n_transitions: |P| and |T|.
        pre: shape (|P|, |T|), int64 CSC: weight of arc p → t.
        post: shape (|P|, |T|), int64 CSC: weight of arc t → p.
        inhibitor: shape (|P|, |T|), int64 CSC: threshold of the inhibitor arc p → t.
        incidence: C = post − pre, shape (|P|, |T|), int64 CSC, explicit zeros removed. Reset arcs
            are not in it: with them a firing's change depends on the marking (see ``reset``).
        m0: the initial marking, shape (|P|,), int64.
        reset: shape (|P|, |T|), int64 CSC: 1 where a reset arc p → t empties p (none: no entries).
    Every CSC matrix has sorted row indices within each column (canonical format).
    """

    n_places: int
    n_transitions: int
    pre: sp.csc_matrix
    post: sp.csc_matrix
    inhibitor: sp.csc_matrix
    incidence: sp.csc_matrix
    m0: np.ndarray
    reset: sp.csc_matrix | None = None

    @property
    def n_arcs(self) -> int:
        """Number of arcs (normal, inhibitor and reset)."""
        return int(self.pre.nnz + self.post.nnz + self.inhibitor.nnz + self.n_resets)

    @property
    def n_resets(self) -> int:
        """Number of reset arcs."""
        return 0 if self.reset is None else int(self.reset.nnz)

    def consumed_or_read(self) -> np.ndarray:
        """Boolean (|P|,): places some transition consumes from, is inhibited by or resets."""
        out = np.zeros(self.n_places, dtype=bool)
        out[self.pre.indices] = True
        out[self.inhibitor.indices] = True
        if self.reset is not None:
            out[self.reset.indices] = True
        return out

    def reset_places(self) -> np.ndarray:
        """Indices of the places some reset arc empties, ascending, (k,) int64."""
        if self.reset is None or not self.reset.nnz:
            return np.zeros(0, dtype=np.int64)
        return np.unique(self.reset.indices).astype(np.int64)

    def markable(self) -> tuple[np.ndarray, np.ndarray]:
        """The places some reachable marking may mark and the transitions that may fire, found
        without a search: a place is markable when initially marked or the output of a transition
        that may fire, and a transition may fire when each of its input places is markable (token
        counts, inhibitor and reset arcs left out, so both sets are over-approximations).

        What is outside them is exact: the unmarkable places form the largest siphon that is
        unmarked at M0, and an unmarked siphon stays unmarked (Murata 1989, section VI-B), so they
        hold no token in any reachable marking and a transition that consumes from one never fires.
        Linear in the number of arcs.

        Returns:
            ``(places, transitions)``: (|P|,) bool, True where the place may be marked; (|T|,)
            bool, True where the transition may fire.
        """
        pre_rows = self.pre.tocsr()
        missing = np.diff(self.pre.indptr).astype(np.int64)  # unmarked input places per transition
        places = np.zeros(self.n_places, dtype=bool)
        fires = np.zeros(self.n_transitions, dtype=bool)
        todo = [int(p) for p in np.flatnonzero(self.m0 > 0)]
        places[todo] = True
        ready = [int(t) for t in np.flatnonzero(missing == 0)]
        while todo or ready:
            while todo:
                p = todo.pop()
                for t in pre_rows.indices[pre_rows.indptr[p]:pre_rows.indptr[p + 1]].tolist():
                    missing[t] -= 1
                    if missing[t] == 0:
                        ready.append(t)
            while ready:
                t = ready.pop()
                fires[t] = True
                for p in self.post.indices[self.post.indptr[t]:self.post.indptr[t + 1]].tolist():
                    if not places[p]:
                        places[p] = True
                        todo.append(p)
        return places, fires

    def lone_input_trap(self) -> tuple[np.ndarray, np.ndarray]:
        """Two structural reasons why some transition is enabled in every reachable marking (so no
        marking is dead), found without a search.

        A transition with no input place and no inhibitor arc is enabled in every marking. A place
        that is the only input place of a transition, by an arc of weight 1, with no inhibitor arc
        on that transition, enables it whenever the place is marked. A trap (a set of places every
        transition that consumes from or resets one of them puts a token back into one of them)
        that is marked at M0 stays marked (Murata 1989, section VI-B, with a reset counted as a
        consumption): if each of its places is such a lone input place, some transition is enabled
        in every reachable marking. The trap returned is the largest one made of lone input places
        (unique: a union of traps is a trap), found by removing, until none is left, the places a
        transition consumes from or resets without putting a token into the set: each round is
        linear in the number of arcs, and each round but the last drops a place.

        Returns:
            ``(sources, trap)``: (|T|,) bool, True for a transition with no input place and no
            inhibitor arc; (|P|,) bool, True for a place of the largest trap of lone input places.
            Some transition is enabled in every reachable marking when ``sources.any()`` or
            ``(trap & (m0 > 0)).any()``.
        """
        inputs = np.diff(self.pre.indptr)
        free = np.diff(self.inhibitor.indptr) == 0
        sources = (inputs == 0) & free
        lone = np.flatnonzero((inputs == 1) & free)
        lone = lone[self.pre.data[self.pre.indptr[lone]] == 1]
        trap = np.zeros(self.n_places, dtype=bool)
        trap[self.pre.indices[self.pre.indptr[lone]]] = True
        touch = self.pre != 0
        if self.reset is not None and self.reset.nnz:
            touch = touch + (self.reset != 0)
        touch_rows = sp.csr_matrix(touch, dtype=np.int64)
        post_cols = sp.csc_matrix(self.post != 0, dtype=np.int64)
        while trap.any():  # each round drops the places a transition takes from without giving back
            gives_back = (post_cols.T @ trap.astype(np.int64)) > 0
            drop = trap & ((touch_rows @ (~gives_back).astype(np.int64)) > 0)
            if not drop.any():
                break
            trap &= ~drop
        return sources, trap

    def firing_rows(self, rows: np.ndarray, t: int) -> np.ndarray:
        """Successors of markings ``rows`` (k, |P|) by transition t (assumed enabled), (k, |P|) int64:
        ``M + C[:, t]``, with the places of t's reset arcs set to ``Post[p, t]``."""
        out: np.ndarray = np.asarray(rows, dtype=np.int64) + self.incidence[:, t].toarray().ravel()[None, :]
        if self.reset is not None and self.reset.nnz:
            for k in range(self.reset.indptr[t], self.reset.indptr[t + 1]):
                p = int(self.reset.indices[k])
                out[:, p] = self.post[p, t]
        return out


def _csc(net: PetriNet, table: object, shape: tuple[int, int]) -> sp.csc_matrix:
    rows: list[int] = []
    cols: list[int] = []
    vals: list[int] = []
    pidx, tidx = net.place_index, net.transition_index
    for tid, places in table.items():  # type: ignore[attr-defined]
        j = tidx[tid]
        for pid, w in places.items():
            rows.append(pidx[pid])
            cols.append(j)
            vals.append(int(w))
    mat = sp.csc_matrix((np.array(vals, dtype=np.int64), (np.array(rows, dtype=np.int64),
                                                          np.array(cols, dtype=np.int64))), shape=shape)
    mat.sum_duplicates()
    mat.sort_indices()
    return mat


def sparse_net(net: PetriNet) -> SparseNet:
    """Return the sparse matrices of ``net`` (built once, then kept on the net object).

    When the net's dense matrices already exist they are converted; otherwise the matrices are built
    from the arc adjacency (``net.input_places``, ``output_places``, ``inhibitor_places``) without
    ever allocating a dense (|P|, |T|) array.
    """
    cached = net.__dict__.get(_CACHE_KEY)
    if isinstance(cached, SparseNet):
        return cached
    shape = (len(net.places), len(net.transitions))
    if all(name in net.__dict__ for name in ("pre", "post", "inhibitor")):
        pre, post, inh = (sp.csc_matrix(np.asarray(getattr(net, name))) for name in ("pre", "post", "inhibitor"))
    else:
        pre = _csc(net, net.input_places, shape)
        post = _csc(net, net.output_places, shape)
        inh = _csc(net, net.inhibitor_places, shape)
    inc = sp.csc_matrix(post - pre)
    inc.eliminate_zeros()
    inc.sort_indices()
    for mat in (pre, post, inh):
        mat.sort_indices()
    m0 = np.zeros(shape[0], dtype=np.int64)
    pidx = net.place_index
    for pid, count in net.initial_marking.items():
        m0[pidx[pid]] = count
    m0.flags.writeable = False
    reset = _csc(net, {tid: {pid: 1 for pid in pids} for tid, pids in net.reset_places.items()}, shape)
    out = SparseNet(n_places=shape[0], n_transitions=shape[1], pre=pre, post=post, inhibitor=inh,
                    incidence=inc, m0=m0, reset=reset)
    net.__dict__[_CACHE_KEY] = out
    return out


def dense_is_cheap(net: PetriNet) -> bool:
    """True when the net's dense matrices exist already or are small (|P|·|T| ≤ :data:`DENSE_LIMIT`)."""
    if "pre" in net.__dict__ and "inhibitor" in net.__dict__ and "incidence" in net.__dict__:
        return True
    return len(net.places) * len(net.transitions) <= DENSE_LIMIT
