"""The services.toml a node loaded: its digest, and whether the file on disk has changed since.

A node tells each client, in ``welcome``, the hex SHA-256 of the services.toml bytes it loaded
(``location``) and whether the file on disk now differs (``location_changed``), so that a
coordinator can refuse to run against a node started from another placement (docs/protocol.md §3).
The check is cheap: a ``stat`` per authenticated connection; the file is read and hashed again only
when its size, times or inode changed.
"""

from __future__ import annotations

import hashlib
import logging
import os

__all__ = ["LocationWatch", "digest_of"]

log = logging.getLogger("petrobot.node")


def digest_of(data: bytes) -> str:
    """Hex SHA-256 of ``data``: how a services.toml is named in ``welcome.location``."""
    return hashlib.sha256(data).hexdigest()


class LocationWatch:
    """Watches one services.toml against the digest of the bytes loaded from it.

    Args:
        path: the file (``None`` or ``"<string>"``: nothing to watch, never changed).
        digest: digest of the bytes the node loaded.
    """

    def __init__(self, path: str | None, digest: str | None) -> None:
        self.path = path if path and path != "<string>" else None
        self.digest = digest
        self._seen: tuple[int, ...] | None = None
        self._changed = False
        if self.path is not None:
            self._seen = self._stat()

    def _stat(self) -> tuple[int, ...] | None:
        assert self.path is not None
        try:
            st = os.stat(self.path)
        except OSError:
            return None
        return st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns

    def changed(self) -> bool:
        """Whether the file on disk differs from what was loaded (removed counts as changed)."""
        if self.path is None or self.digest is None:
            return False
        seen = self._stat()
        if seen == self._seen:
            return self._changed
        self._seen = seen
        try:
            with open(self.path, "rb") as fh:
                now = digest_of(fh.read())
        except OSError:
            now = None
        was = self._changed
        self._changed = now != self.digest
        if self._changed and not was:
            log.warning("%s changed on disk since this node loaded it: restart the node to apply it", self.path)
        return self._changed
