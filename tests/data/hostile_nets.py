"""Generators of the nets that used to take ``petrobot analyze`` down, and of nets whose invariant
enumeration explodes while a linear program decides them at once.

Run as a script to write the files::

    python tests/data/hostile_nets.py OUTDIR

which writes ``ring20000.toml`` (20,000 places and 20,000 transitions in one ring, one token:
about 2 MB of TOML; it used to reach 18 GB of memory in a minute, the dense |P|×|T| matrices and
the Farkas table), ``ring500.toml`` (the 500-place ring that took 35 s), ``choices16.toml`` and
``choices24.toml`` (see :func:`choices_toml`). The tests import this module by path and write the
files they need into a temporary directory.
"""

from __future__ import annotations

import sys
from pathlib import Path


def ring_toml(n: int, tokens: int = 1) -> str:
    """A ring of ``n`` places p0..p{n-1} and ``n`` transitions t_i: p_i → p_{i+1 mod n}; ``tokens``
    tokens in p0. Bounded, live, reversible, conservative and consistent; n·C(n+tokens-1, tokens)/n
    reachable markings (n for one token)."""
    out = [f'[net]\nname = "ring{n}"\n']
    for i in range(n):
        out.append(f'[[place]]\nid = "p{i}"\n' + (f"tokens = {tokens}\n" if i == 0 else ""))
    for i in range(n):
        out.append(f'[[transition]]\nid = "t{i}"\ninputs = {{ p{i} = 1 }}\noutputs = {{ p{(i + 1) % n} = 1 }}\n')
    return "\n".join(out)


def choices_toml(k: int) -> str:
    """A net whose minimal P- and T-semiflows number 2**k each, with k·k reachable markings.

    Two rings of k stages share nothing but their length:

    * the *choice ring*: place a_i, two transitions u_i and v_i both a_i → a_{i+1}: a T-semiflow
      picks u_i or v_i at each stage (2**k minimal ones), and the all-ones vector is a strictly
      positive T-semiflow, so the net is consistent;
    * the *fork ring*: places q_i and r_i, one transition j_i: q_i + r_i → q_{i+1} + r_{i+1}: a
      P-semiflow picks q_i or r_i at each stage (2**k minimal ones), and the all-ones vector is a
      strictly positive P-semiflow, so the net is conservative.

    One token in a_0, one in q_0 and one in r_0: the reachable markings are the k positions of each
    ring, k·k in all, every transition live. The Farkas enumeration of either kind of invariant
    needs 2**k rows; a linear program decides consistency and conservativeness at once.
    """
    out = [f'[net]\nname = "choices{k}"\n']
    for i in range(k):
        out.append(f'[[place]]\nid = "a{i}"\n' + ("tokens = 1\n" if i == 0 else ""))
    for i in range(k):
        for side in ("q", "r"):
            out.append(f'[[place]]\nid = "{side}{i}"\n' + ("tokens = 1\n" if i == 0 else ""))
    for i in range(k):
        nxt = (i + 1) % k
        for name in ("u", "v"):
            out.append(f'[[transition]]\nid = "{name}{i}"\ninputs = {{ a{i} = 1 }}\noutputs = {{ a{nxt} = 1 }}\n')
        out.append(f'[[transition]]\nid = "j{i}"\ninputs = {{ q{i} = 1, r{i} = 1 }}\n'
                   f'outputs = {{ q{nxt} = 1, r{nxt} = 1 }}\n')
    return "\n".join(out)


def write_all(folder: Path) -> list[Path]:
    """Write every hostile net into ``folder``; return the paths."""
    folder.mkdir(parents=True, exist_ok=True)
    files = {"ring20000.toml": ring_toml(20_000), "ring500.toml": ring_toml(500),
             "choices16.toml": choices_toml(16), "choices24.toml": choices_toml(24)}
    paths = []
    for name, text in files.items():
        path = folder / name
        path.write_text(text, encoding="utf-8")
        paths.append(path)
    return paths


if __name__ == "__main__":
    for written in write_all(Path(sys.argv[1] if len(sys.argv) > 1 else ".")):
        print(written, written.stat().st_size, "bytes")
