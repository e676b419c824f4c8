"""The shared key that authenticates coordinator↔node connections (docs/protocol.md, "Handshake").

Where the key comes from, first match wins:

1. an explicit key file, the ``key_file`` argument (the ``--key-file`` option);
2. the environment variable ``PETROBOT_KEY``: hex digits (an even number, at least 32) are decoded,
   anything else is taken as UTF-8 text;
3. the key file named by ``PETROBOT_KEY_FILE``, else ``~/.config/petrobot/key``.

A key file's content (surrounding whitespace stripped) is read the same way as the variable.

If the key file does not exist it is created with mode 0600 and 32 random bytes written as hex,
and a log line says so: enough for a one-machine setup. For several hosts, copy that file.
"""

from __future__ import annotations

import logging
import os
import secrets
import string
from pathlib import Path

from services.errors import PetrobotError

__all__ = ["DEFAULT_KEY_FILE", "SharedKeyError", "decode_key", "default_key_path", "load_key"]

log = logging.getLogger("petrobot.keys")

DEFAULT_KEY_FILE = Path("~/.config/petrobot/key")
"""Key file used when neither ``--key-file`` nor ``PETROBOT_KEY_FILE`` is given."""


class SharedKeyError(PetrobotError):
    """The shared key cannot be read (empty key, unreadable file)."""


def decode_key(text: str) -> bytes:
    """Turn the text of ``PETROBOT_KEY`` or a key file into key bytes.

    Args:
        text: hex digits (even count, >= 32 digits) or any other text.

    Returns:
        The decoded hex, or the UTF-8 bytes of the stripped text.

    Raises:
        SharedKeyError: the text is empty.
    """
    text = text.strip()
    if not text:
        raise SharedKeyError("the shared key is empty")
    if len(text) >= 32 and len(text) % 2 == 0 and all(c in string.hexdigits for c in text):
        return bytes.fromhex(text)
    return text.encode("utf-8")


def default_key_path(key_file: str | os.PathLike[str] | None = None) -> Path:
    """The key file to use: ``key_file``, else ``$PETROBOT_KEY_FILE``, else the default."""
    if key_file is not None:
        return Path(key_file).expanduser()
    env = os.environ.get("PETROBOT_KEY_FILE")
    if env:
        return Path(env).expanduser()
    return DEFAULT_KEY_FILE.expanduser()


def load_key(key_file: str | os.PathLike[str] | None = None, *, create: bool = True) -> bytes:
    """Load the shared key (see the module docstring for the order of sources).

    Args:
        key_file: explicit key file (the ``--key-file`` option), or ``None``.
        create: create a fresh key file if the chosen one does not exist.

    Returns:
        The key bytes.

    Raises:
        SharedKeyError: the key is empty, or the file is missing (with ``create=False``) or unreadable.
    """
    env = os.environ.get("PETROBOT_KEY")
    if env is not None and key_file is None:
        return decode_key(env)
    path = default_key_path(key_file)
    if not path.exists():
        if not create:
            raise SharedKeyError(f"{path}: key file does not exist")
        path.parent.mkdir(parents=True, exist_ok=True)
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        except FileExistsError:  # another process created it first: use theirs
            pass
        else:
            with os.fdopen(fd, "w") as fh:
                fh.write(secrets.token_hex(32) + "\n")
            log.warning("created a new shared key file %s (mode 0600); copy it to every host", path)
    try:
        return decode_key(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise SharedKeyError(f"{path}: cannot read key file: {exc}") from exc
