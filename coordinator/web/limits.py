"""What pages without the console's token may cost the run the console follows (pure: no I/O).

The console shares its event loop with the run it shows (docs/console.md). A read-only page rightly
may not steer the run, but it may still ask for work: validate or export a drawing, replay a run,
and it takes frames. Without bounds, four read-only pages validating 2.7 MB drawings took a run from
2,000 firings a second to 4, and 200 idle viewers cost it 27 % (issue 22). :class:`ConsoleGuard`
decides, from :class:`ConsoleLimits`:

* **viewers**: at most ``max_viewers`` read-only pages at once; one more is closed at its
  ``hello`` (WebSocket code 1013, try again later). Pages with the token are not counted. A
  read-only page the console closes for breaking a bound (a message too large, work over the
  budget, a protocol violation) costs its address a token of a bucket of ``closures``, earned back
  one every ``closure_refill_s``; an address with none left has its next read-only pages closed at
  their ``hello`` (1013), before they can send anything large: a page that reconnects as soon as it
  is closed no longer makes the console read megabytes each time;
* **work** (validation and export of a drawing, a replay): a read-only page's drawing is at most
  ``viewer_bytes`` of JSON (a page's message over that is closed unread, an HTTP body refused with
  413); read-only jobs come from one token bucket for all such pages (``viewer_jobs_per_s``,
  bursts of ``viewer_job_burst``) and at most ``viewer_queue`` of them wait for the worker at once;
  anyone's jobs wait at most ``max_queue`` deep. The work itself runs in the console's worker
  process (:mod:`coordinator.web.worker`), never on the event loop, except small drawings of pages
  with the token (at most ``small_bytes``), checked in a thread as they are drawn;
* **tokens**: a wrong token costs its address a token of a bucket of ``token_failures``, earned back
  one every ``token_refill_s``; an address with none left gets its wrong tokens refused at once
  (WebSocket closed with code 1008, HTTP 429) before any other work. The right token is always
  taken: a page guessing beside the operator on the same host never locks the operator out.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

from services.node.guard import TokenBuckets

__all__ = ["ConsoleGuard", "ConsoleLimits"]


@dataclass(frozen=True, slots=True)
class ConsoleLimits:
    """The bounds of :class:`ConsoleGuard` (module docstring).

    Attributes:
        max_viewers: read-only pages at once.
        viewer_bytes: largest message (or HTTP body) a read-only page may send, bytes.
        small_bytes: a drawing of a page with the token up to this size (bytes of its message) is
            checked in a thread; larger ones go to the worker.
        viewer_jobs_per_s: jobs of read-only pages per second, all together, in the long run.
        viewer_job_burst: jobs read-only pages may ask for at once, all together.
        viewer_queue: jobs of read-only pages waiting for the worker at once.
        max_queue: jobs of any page waiting for the worker at once.
        token_failures: wrong tokens an address may give in a row.
        token_refill_s: seconds for an address to earn back one wrong token.
        closures: read-only pages of an address the console may close for breaking a bound, in a row.
        closure_refill_s: seconds for an address to earn back one such closure.
    """

    max_viewers: int = 32
    viewer_bytes: int = 512 * 1024
    small_bytes: int = 64 * 1024
    viewer_jobs_per_s: float = 2.0
    viewer_job_burst: int = 4
    viewer_queue: int = 1
    max_queue: int = 8
    token_failures: int = 10
    token_refill_s: float = 2.0
    closures: int = 4
    closure_refill_s: float = 5.0


class ConsoleGuard:
    """Counts read-only pages, jobs and wrong tokens against :class:`ConsoleLimits`.

    Args:
        limits: the bounds.
        clock: monotonic clock, seconds (pass one in tests).
    """

    def __init__(self, limits: ConsoleLimits = ConsoleLimits(), clock: Callable[[], float] = time.monotonic) -> None:
        self.limits = limits
        self._clock = clock
        self.viewers = 0
        """Read-only pages now."""
        self.queued = 0
        """Jobs asked for and not done yet (running or waiting)."""
        self.viewer_queued = 0
        """Of which read-only pages'."""
        self.refused = 0
        """Jobs and pages refused so far (viewers over the cap, jobs over a bound, wrong tokens throttled)."""
        self._jobs = TokenBuckets(burst=limits.viewer_job_burst, per_s=limits.viewer_jobs_per_s, max_hosts=1)
        self._tokens = TokenBuckets(burst=limits.token_failures, per_s=1.0 / limits.token_refill_s)
        self._closures = TokenBuckets(burst=limits.closures, per_s=1.0 / limits.closure_refill_s)

    # ---- pages
    def viewer_joins(self, host: str) -> str | None:
        """A read-only page from ``host`` said hello: ``None`` if it may stay (it is counted then),
        else why not, in words."""
        if self._closures.tokens(host, self._clock()) < 1.0:
            self.refused += 1
            return "read-only pages from this address broke the console's bounds too often: wait"
        if self.viewers >= self.limits.max_viewers:
            self.refused += 1
            return f"{self.viewers} read-only pages already: close one, or open the URL with its token"
        self.viewers += 1
        return None

    def viewer_closed(self, host: str) -> None:
        """A read-only page from ``host`` was closed for breaking a bound (module docstring)."""
        self._closures.spend(host, self._clock())

    def viewer_leaves(self) -> None:
        """A read-only page counted by :meth:`viewer_joins` closed."""
        self.viewers = max(0, self.viewers - 1)

    # ---- tokens
    def wrong_token(self, host: str) -> bool:
        """``host`` gave a wrong token: whether it may still be answered (False: refuse it at once)."""
        now = self._clock()
        if not self._tokens.take(host, now):
            self.refused += 1
            return False
        return True

    # ---- work
    def may_work(self, control: bool, size: int) -> str | None:
        """Whether a job of ``size`` bytes may be asked for by a page with (``control``) or without
        the token; if it may (``None``), it is counted until :meth:`work_done`. Otherwise the reason
        it is refused, in words."""
        limits = self.limits
        if not control:
            if size > limits.viewer_bytes:
                self.refused += 1
                return (f"a read-only page may send drawings of at most {limits.viewer_bytes >> 10} KiB "
                        f"(this one is {size >> 10} KiB): open the URL with its token")
            if self.viewer_queued >= limits.viewer_queue or not self._jobs.take("*", self._clock()):
                self.refused += 1
                return "the console is busy with read-only pages' work: try again in a moment"
        if self.queued >= limits.max_queue:
            self.refused += 1
            return "the console is busy: try again in a moment"
        self.queued += 1
        self.viewer_queued += not control
        return None

    def work_done(self, control: bool) -> None:
        """A job counted by :meth:`may_work` ended (done or failed)."""
        self.queued = max(0, self.queued - 1)
        if not control:
            self.viewer_queued = max(0, self.viewer_queued - 1)
