"""The shared key that authenticates coordinator↔node connections (docs/protocol.md §3, "The shared key").

Where the key comes from, first match wins:

1. an explicit key file, the ``key_file`` argument (the ``--key-file`` option);
2. the environment variable ``PETROBOT_KEY``: hex digits (an even number, at least 32) are decoded,
   anything else is taken as UTF-8 text;
3. the key file named by ``PETROBOT_KEY_FILE``, else ``~/.config/petrobot/key``.

A key file holds one key per non-empty line, each read the same way as the variable (surrounding
whitespace stripped): the first line is *the* key, used to connect; the lines after it are previous
keys that a node still accepts while a new key is rolled out (key rotation, docs/protocol.md §3).

Rules a key must meet:

* at least :data:`MIN_KEY_BYTES` (16) bytes once decoded: a shorter key is refused, since a node
  answers guesses and a short key can be guessed;
* not weak (:func:`key_weakness`): a key whose bytes repeat a short pattern (16 zero bytes,
  ``passwordpassword``), count up (``0123456789abcdef``, ``bytes(range(32))``) or are too
  few and too repetitive by their frequencies is refused as a short one is: it is long without being
  hard to guess;
* a key file must not be writable by other users (group or others write bits, or an owner other
  than the current user or root): whoever can write it can replace the key. A key file readable by
  other users is accepted with a warning (chmod 600 it).

If the key file does not exist it is created with mode 0600 and 32 random bytes written as hex,
and a log line says so: enough for a one-machine setup. For several hosts, copy that file.
"""

from __future__ import annotations

import collections
import logging
import math
import os
import secrets
import stat
import string
from pathlib import Path
from typing import Final

from services.errors import PetrobotError

__all__ = [
    "DEFAULT_KEY_FILE",
    "MIN_KEY_BYTES",
    "SharedKeyError",
    "check_key",
    "decode_key",
    "default_key_path",
    "key_weakness",
    "load_key",
    "load_keys",
]

log = logging.getLogger("petrobot.keys")

DEFAULT_KEY_FILE = Path("~/.config/petrobot/key")
"""Key file used when neither ``--key-file`` nor ``PETROBOT_KEY_FILE`` is given."""
MIN_KEY_BYTES: Final = 16
"""Shortest key accepted, bytes (128 bits)."""
MIN_KEY_SPREAD_BITS: Final = 40.0
"""Least spread accepted: the key's length times the Shannon entropy of its byte frequencies, bits.
16 random bytes score about 60 (at most 64: 16 distinct bytes), 32 random bytes about 150; 16 bytes
holding 5 values equally often score 37."""

_HOW_TO_MAKE = "make one with: python -c 'import secrets; print(secrets.token_hex(32))'"


class SharedKeyError(PetrobotError):
    """The shared key cannot be used (empty or too short, unreadable or unsafe file)."""


def key_weakness(key: bytes) -> str | None:
    """Why ``key`` is weak although long enough, or ``None``.

    A key is weak when its bytes repeat a pattern of at most half its length, go from one to the
    next by at most two different steps (mod 256: ``0123…9abc…``), or spread over too few values (:data:`MIN_KEY_SPREAD_BITS`). These are the keys a
    person types or a test writes (``00…00``, ``abab…``, ``0123…``); a key from
    :func:`secrets.token_hex` never is.
    """
    n = len(key)
    if n < 2:
        return None
    for period in range(1, n // 2 + 1):
        if key[period:] == key[:-period]:
            return f"it repeats a pattern of {period} byte{'s' * (period > 1)}"
    steps = {(key[i + 1] - key[i]) % 256 for i in range(n - 1)}
    if len(steps) <= 2:
        return "its bytes go up or down by one or two constant steps (a counting sequence)"
    counts = collections.Counter(key).values()
    spread = -n * sum(c / n * math.log2(c / n) for c in counts)
    if spread < MIN_KEY_SPREAD_BITS:
        return (f"its bytes take {len(counts)} values, about {spread:.0f} bits by their frequencies "
                f"(at least {MIN_KEY_SPREAD_BITS:.0f}; 16 random bytes give about 60)")
    return None


def check_key(key: bytes, where: str = "the shared key") -> bytes:
    """Return ``key`` if it is long enough and not weak (:func:`key_weakness`).

    Raises:
        SharedKeyError: ``key`` is shorter than :data:`MIN_KEY_BYTES`, or weak.
    """
    if len(key) < MIN_KEY_BYTES:
        raise SharedKeyError(f"{where} is {len(key)} bytes; at least {MIN_KEY_BYTES} are needed ({_HOW_TO_MAKE})")
    weak = key_weakness(key)
    if weak is not None:
        raise SharedKeyError(f"{where} is weak: {weak}; a key must be hard to guess ({_HOW_TO_MAKE})")
    return key


def decode_key(text: str, where: str = "the shared key") -> bytes:
    """Turn the text of ``PETROBOT_KEY`` or of one key-file line into key bytes.

    Args:
        text: hex digits (even count, >= 32 digits) or any other text.
        where: what the text came from, for error messages.

    Returns:
        The decoded hex, or the UTF-8 bytes of the stripped text.

    Raises:
        SharedKeyError: the text is empty, or the key is shorter than :data:`MIN_KEY_BYTES`.
    """
    text = text.strip()
    if not text:
        raise SharedKeyError(f"{where} is empty")
    if len(text) >= 32 and len(text) % 2 == 0 and all(c in string.hexdigits for c in text):
        return check_key(bytes.fromhex(text), where)
    return check_key(text.encode("utf-8"), where)


def default_key_path(key_file: str | os.PathLike[str] | None = None) -> Path:
    """The key file to use: ``key_file``, else ``$PETROBOT_KEY_FILE``, else the default."""
    if key_file is not None:
        return Path(key_file).expanduser()
    env = os.environ.get("PETROBOT_KEY_FILE")
    if env:
        return Path(env).expanduser()
    return DEFAULT_KEY_FILE.expanduser()


def _check_mode(path: Path, st: os.stat_result) -> None:
    mode = stat.S_IMODE(st.st_mode)
    if mode & (stat.S_IWGRP | stat.S_IWOTH):
        raise SharedKeyError(f"{path}: key file is writable by other users (mode {mode:04o}); run: chmod 600 {path}")
    if st.st_uid not in (os.geteuid(), 0):
        raise SharedKeyError(f"{path}: key file is owned by another user (uid {st.st_uid}); "
                             "whoever owns it can replace the key")
    if mode & (stat.S_IRGRP | stat.S_IROTH):
        log.warning("key file %s is readable by other users (mode %04o): run chmod 600 %s", path, mode, path)


def load_keys(key_file: str | os.PathLike[str] | None = None, *, create: bool = True) -> tuple[bytes, ...]:
    """Load the shared key and any previous keys (see the module docstring for the sources).

    Args:
        key_file: explicit key file (the ``--key-file`` option), or ``None``.
        create: create a fresh key file if the chosen one does not exist.

    Returns:
        The key, then the previous keys still accepted (a node accepts them all; a client uses the
        first).

    Raises:
        SharedKeyError: a key is empty or too short, or the file is missing (with ``create=False``),
            unreadable, or writable by other users.
    """
    env = os.environ.get("PETROBOT_KEY")
    if env is not None and key_file is None:
        return (decode_key(env, "PETROBOT_KEY"),)
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
        with open(path, encoding="utf-8") as fh:
            _check_mode(path, os.fstat(fh.fileno()))
            lines = [(n, line) for n, line in enumerate(fh.read().splitlines(), 1) if line.strip()]
    except (OSError, UnicodeDecodeError) as exc:
        raise SharedKeyError(f"{path}: cannot read key file: {exc}") from exc
    if not lines:
        raise SharedKeyError(f"{path}: the key file is empty")
    return tuple(decode_key(line, f"{path}: the key on line {n}") for n, line in lines)


def load_key(key_file: str | os.PathLike[str] | None = None, *, create: bool = True) -> bytes:
    """Load the shared key: the first of :func:`load_keys` (the one a client connects with).

    Raises:
        SharedKeyError: as :func:`load_keys`.
    """
    return load_keys(key_file, create=create)[0]
