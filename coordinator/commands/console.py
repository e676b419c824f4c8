"""``petrobot console [NET...] [--journal FILE]``: the graphical operator console in a browser (paper section 5).

Serves the web console (:mod:`coordinator.web`) for designing nets by drawing them and replaying
runs from a journal; no node is needed. ``petrobot run NET --console [HOST:]PORT`` serves the same
page attached to a live run. Both print the page's address with its secret token; a page opened
without the token is read-only. The server listens on the loopback address unless ``--bind-any``
allows another one.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from coordinator.commands import options
from services.errors import PetrobotError

__all__ = ["add_listen_options", "add_parser", "parse_listen", "run", "start_console"]

#: Where the console listens by default.
DEFAULT_LISTEN = "127.0.0.1:8765"

DESCRIPTION = """\
Serve the operator console, a web page (open the printed address in a browser): draw a task net
with the mouse (places, transitions, arcs, primitive tasks and their actions, events), checked as
you draw with the rules of `petrobot check` (and against services.toml: which node hosts each
action); save it as a TOML net file with the drawing's positions; open TOML and PNML; export PNML,
DOT and PNG; replay the runs of a journal; run analyze, gspn, perf and learn on the drawn net and
see their results on it. Nets and journals are read, and nets saved, under the current folder
(--root) only.

Runs: the page starts a net file on the nodes of services.toml, or resumes an interrupted run,
with the same preflight as `petrobot run` (every primitive action placed and offered by a reachable
node), and follows several runs at once; they are written to --journal (default
ROOT/runs/journal.sqlite) and interrupted, resumable, when the console stops. To serve the page
attached to a run started on the command line, use `petrobot run NET --console [HOST:]PORT`.

The printed address carries a secret token: the page opened with it may save files, start and
steer runs; without it the page is read-only."""


def parse_listen(text: str) -> tuple[str, int]:
    """``PORT``, ``HOST:PORT`` or ``[IPv6]:PORT`` → ``(host, port)``; the host defaults to 127.0.0.1.

    Raises:
        PetrobotError: not of that form, or a port outside 0–65535.
    """
    host, port = "127.0.0.1", text.strip()
    if port.startswith("["):
        close = port.find("]")
        if close < 0 or port[close + 1:close + 2] != ":":
            raise PetrobotError(f"bad address {text!r}: use PORT, HOST:PORT or [IPv6]:PORT")
        host, port = port[1:close], port[close + 2:]
    elif ":" in port:
        host, port = port.rsplit(":", 1)
    try:
        number = int(port)
    except ValueError:
        raise PetrobotError(f"bad port in {text!r}: use PORT, HOST:PORT or [IPv6]:PORT") from None
    if not 0 <= number <= 65535:
        raise PetrobotError(f"port {number} is outside 0-65535")
    return host or "127.0.0.1", number


def add_listen_options(parser: argparse.ArgumentParser) -> None:
    """``--bind-any``: the explicit consent to listen on an address other than loopback."""
    parser.add_argument("--bind-any", action="store_true",
                        help="allow listening on an address that is not loopback (the console is then reachable "
                             "from the network; anyone with the printed token can steer runs)")


def add_parser(subparsers: Any) -> None:
    """Register ``console`` on the ``petrobot`` sub-command parser."""
    p = subparsers.add_parser("console", help="the operator console in a browser: draw nets, replay runs",
                              description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("nets", nargs="*", metavar="NET", help="net files to open (.toml, .pnml, .xml)")
    p.add_argument("--journal", metavar="FILE", default=None, help="SQLite journal whose runs to replay")
    p.add_argument("--services", metavar="FILE", default=None,
                   help="location file placement is checked against (default: ./services.toml if it exists)")
    p.add_argument("--listen", metavar="[HOST:]PORT", default=DEFAULT_LISTEN,
                   help="address to listen on (default: %(default)s; port 0 picks a free port)")
    p.add_argument("--root", metavar="DIR", default=".",
                   help="folder the page may open and save net files in (default: the current folder)")
    options.add_key_file(p)
    add_listen_options(p)
    p.set_defaults(func=run)


def _location(path: str | None) -> Any:
    from services.location import load_location

    if path is None:
        if not Path("services.toml").exists():
            return None
        path = "services.toml"
    return load_location(path)


async def start_console(*, nets: list[Path], journal: Path | None, services: str | None, listen: str,
                        bind_any: bool, root: Path, key_file: str | None = None) -> Any:
    """Start a :class:`~coordinator.web.server.ConsoleServer` and print its address.

    Raises:
        PetrobotError: a bad address, an unreadable services.toml, a non-loopback host without
            ``bind_any``, or an address that cannot be bound.
    """
    from coordinator.web.server import ConsoleConfig, ConsoleServer, is_loopback

    host, port = parse_listen(listen)
    if not bind_any and not is_loopback(host):
        raise PetrobotError(f"{host} is not a loopback address: the console would be reachable from the network; "
                            "add --bind-any to listen there anyway")
    config = ConsoleConfig(root=root, nets=nets, journal=journal, location=_location(services), host=host,
                           port=port, bind_any=bind_any, key_file=key_file)
    server = ConsoleServer(config)
    try:
        url = await server.start()
    except OSError as exc:
        raise PetrobotError(f"cannot listen on {listen}: {exc.strerror or exc}") from None
    if not is_loopback(host):
        print(f"petrobot console: WARNING: listening on {host}, reachable from the network; the token in the "
              "address below gives control of runs: share it with care", file=sys.stderr, flush=True)
    print(f"petrobot console: {url}", flush=True)
    return server


def run(args: argparse.Namespace) -> int:
    """Serve until Ctrl-C; 0, or 2 on a bad option."""
    import asyncio

    root = Path(args.root)
    nets = [Path(n) for n in args.nets]
    for net in nets:
        if not net.is_file():
            print(f"petrobot console: {net}: no such net file", file=sys.stderr)
            return 2
    journal = Path(args.journal) if args.journal else None
    if journal is not None and not journal.is_file():
        print(f"petrobot console: {journal}: no such journal file", file=sys.stderr)
        return 2

    async def serve() -> None:
        server = await start_console(nets=nets, journal=journal, services=args.services, listen=args.listen,
                                     bind_any=args.bind_any, root=root, key_file=args.key_file)
        print("  open it in a browser; Ctrl-C stops the console", flush=True)
        try:
            await asyncio.Event().wait()
        finally:
            await server.close()

    try:
        asyncio.run(serve())
    except PetrobotError as exc:
        print(f"petrobot console: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 0
    return 0
