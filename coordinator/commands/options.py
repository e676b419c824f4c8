"""Options shared by the ``petrobot`` commands, defined once.

Each ``add_*`` function adds one option (or one group) to a command's parser with the same name,
meaning and default everywhere; a command may give its own default or help text where its use
differs (``demo`` runs the project's own ``services.toml``). :func:`parse_pairs` reads the
``NAME=VALUE`` options (``--ext-rate``, ``--goal``). Only :mod:`argparse` is imported here, so
building the command line stays cheap.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from typing import Any

from services.errors import PetrobotError

__all__ = [
    "DEFAULT_SERVICES",
    "KEY_FILE_HELP",
    "add_ext_rate",
    "add_journal",
    "add_json",
    "add_key_file",
    "add_max_seconds",
    "add_run",
    "add_seed",
    "add_services",
    "add_view",
    "parse_pairs",
    "report_damage",
]

#: Damaged records a command lists on stderr before it counts the rest.
SHOWN_DAMAGE = 20

#: The location file a command reads unless told otherwise.
DEFAULT_SERVICES = "services.toml"

#: Where the shared key comes from when ``--key-file`` is not given.
KEY_FILE_HELP = ("shared key file (default: $PETROBOT_KEY, else $PETROBOT_KEY_FILE, else "
                 "~/.config/petrobot/key, created if missing)")


def add_services(parser: argparse.ArgumentParser, *, default: str | None = DEFAULT_SERVICES,
                 help: str | None = None) -> None:
    """``--services FILE``: the location file (which node hosts which primitive action, section 5)."""
    parser.add_argument("--services", default=default, metavar="FILE",
                        help=help or "location file (default: %(default)s)")


def add_journal(parser: argparse.ArgumentParser, *, default: str | None = None, required: bool = False,
                help: str | None = None) -> None:
    """``--journal FILE``: the SQLite journal of the runs (:mod:`coordinator.journal`)."""
    parser.add_argument("--journal", default=default, required=required, metavar="FILE",
                        help=help or "SQLite journal of the runs")


def add_run(parser: argparse.ArgumentParser) -> None:
    """``--run RUN_ID``: restrict a journal's analysis to one run (default: every run)."""
    parser.add_argument("--run", metavar="RUN_ID", default=None,
                        help="use the records of this run of the journal only (default: every run)")


def add_key_file(parser: argparse.ArgumentParser, *, help: str | None = None) -> None:
    """``--key-file FILE``: the key shared by the coordinator and the nodes."""
    parser.add_argument("--key-file", default=None, metavar="FILE", help=help or KEY_FILE_HELP)


def add_seed(parser: argparse.ArgumentParser, *, default: int = 0, help: str | None = None) -> None:
    """``--seed N``: the seed that makes a run or an estimate reproducible."""
    parser.add_argument("--seed", type=int, default=default,
                        help=help or "seed of random switches and learners (default: %(default)s)")


def add_max_seconds(parser: argparse.ArgumentParser, *, default: float | None = None) -> None:
    """``--max-seconds S``: end a run after S seconds (a safety net for unattended runs): end state
    ``deadline``, running primitive actions cancelled (a run waiting at home ends ``completed``)."""
    parser.add_argument("--max-seconds", type=float, default=default, metavar="S",
                        help="end the run after this many seconds (end state deadline; running actions are "
                             "cancelled)"
                             + ("" if default is None else " (default: %(default)s)"))


def add_view(parser: argparse.ArgumentParser, *, quiet: bool = False) -> None:
    """``--live`` / ``--lines`` (and ``--quiet``): how the console shows a run."""
    view = parser.add_mutually_exclusive_group()
    view.add_argument("--live", dest="live", action="store_true", default=None,
                      help="redraw a live screen (default on a terminal)")
    view.add_argument("--lines", dest="live", action="store_false", help="print one line per event")
    if quiet:
        parser.add_argument("--quiet", action="store_true", help="print only errors and the summary")


def add_json(parser: argparse.ArgumentParser, *, help: str | None = None) -> None:
    """``--json``: print the report as JSON."""
    parser.add_argument("--json", action="store_true", help=help or "print the report as JSON")


def add_ext_rate(parser: argparse.ArgumentParser, *, help: str) -> None:
    """``--ext-rate TOPIC=RATE`` (repeatable): the rate in 1/s of an external event in the GSPN view."""
    parser.add_argument("--ext-rate", action="append", metavar="TOPIC=RATE", help=help)


def parse_pairs(items: list[str] | None, what: str, cast: Callable[[str], Any] = float) -> dict[str, Any]:
    """Parse ``NAME=VALUE`` arguments into a dict.

    Raises:
        PetrobotError: on an item without ``=`` or a bad value.
    """
    out: dict[str, Any] = {}
    for item in items or []:
        name, sep, value = item.partition("=")
        try:
            if not sep:
                raise ValueError
            out[name.strip()] = cast(value)
        except ValueError:
            raise PetrobotError(f"bad {what} {item!r}: expected NAME=VALUE") from None
    return out


def report_damage(prog: str, lines: Sequence[str]) -> int:
    """Print on stderr the damaged journal records a command skipped (each naming its table, row
    and field: :meth:`coordinator.journal.JournalReader.damage_report`), at most
    :data:`SHOWN_DAMAGE` of them and a count of the rest.

    Returns:
        The command's exit status: 2 when records were skipped, else 0.
    """
    if not lines:
        return 0
    for line in lines[:SHOWN_DAMAGE]:
        print(f"{prog}: damaged record skipped: {line}", file=sys.stderr)
    if len(lines) > SHOWN_DAMAGE:
        print(f"{prog}: ... and {len(lines) - SHOWN_DAMAGE} more damaged record line(s)", file=sys.stderr)
    print(f"{prog}: the journal is damaged: what is shown leaves those records out (exit status 2)", file=sys.stderr)
    return 2
