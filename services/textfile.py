"""Reading an input text file defensively: a size cap, UTF-8 only, no NUL (docs/netfile.md, "Limits");
writing one so that a crash leaves the old file or the new one, never half of it.

Net files (TOML, PNML) and the location file ``services.toml`` are read through here, so that a
binary file, a UTF-16 file, a NUL byte, a device or a file too large to be a plausible input is
refused with its line before any parser sees it. The functions raise :class:`TextProblem`, which
carries no file name: each reader turns it into its own error (``NetFileError``,
``LocationError``) with the path. Pure except :func:`read_capped`, which reads one file, and
:func:`write_atomically`, which writes one.
"""

from __future__ import annotations

import os
import stat
import tempfile
from pathlib import Path

from services.errors import PetrobotError

__all__ = ["MAX_FILE_BYTES", "TextProblem", "decode_utf8", "read_capped", "screen_text", "size_text",
           "write_atomically"]

#: Largest input file read, bytes (16 MiB). Net files of a thousand places are tens of kilobytes;
#: the cap is far above any real file and below what the parsers handle in seconds.
MAX_FILE_BYTES = 16 * 2**20

_BOMS = (
    (b"\xff\xfe\x00\x00", "UTF-32"),
    (b"\x00\x00\xfe\xff", "UTF-32"),
    (b"\xff\xfe", "UTF-16"),
    (b"\xfe\xff", "UTF-16"),
)
_UTF8_BOM = b"\xef\xbb\xbf"


class TextProblem(PetrobotError):
    """An input text is unusable.

    Attributes:
        problem: the problem in words.
        line: 1-based line of the offending byte, or ``None`` for the file as a whole.
    """

    def __init__(self, problem: str, line: int | None = None) -> None:
        super().__init__(problem)
        self.problem = problem
        self.line = line


def read_capped(path: str | os.PathLike[str], *, what: str = "file", limit: int = MAX_FILE_BYTES) -> bytes:
    """Read a regular file of at most ``limit`` bytes.

    Devices, pipes and directories are refused before they are opened for reading, so that
    ``/dev/zero`` or a FIFO cannot make the reader hang or fill memory.

    Args:
        path: the file.
        what: what the file is, for messages (``"net file"``).
        limit: largest accepted size, bytes.

    Raises:
        TextProblem: the file cannot be read or is not a regular file (no line), or is larger than
            ``limit`` (line 1: the file as a whole).
    """
    try:
        info = os.stat(path)
        if not stat.S_ISREG(info.st_mode):
            kind = "a directory" if stat.S_ISDIR(info.st_mode) else "not a regular file"
            raise TextProblem(f"cannot read {what}: {kind}")
        if info.st_size > limit:
            raise TextProblem(f"{what} too large: {info.st_size} bytes (the limit is {size_text(limit)})", 1)
        with open(path, "rb") as fh:
            data = fh.read(limit + 1)
    except OSError as exc:
        raise TextProblem(f"cannot read {what}: {exc.strerror or exc}") from None
    if len(data) > limit:  # grew while we read it
        raise TextProblem(f"{what} too large: more than {size_text(limit)}", 1)
    return data


def size_text(n: int) -> str:
    """A size limit in words: ``16 MiB``, or bytes when not a whole number of MiB."""
    return f"{n // 2**20} MiB" if n % 2**20 == 0 else f"{n} bytes"


def _line_col(data: bytes | str, offset: int) -> tuple[int, int]:
    nl = b"\n" if isinstance(data, bytes) else "\n"
    line = data.count(nl, 0, offset) + 1  # type: ignore[arg-type]
    start = data.rfind(nl, 0, offset) + 1  # type: ignore[arg-type]
    return line, offset - start + 1


def decode_utf8(data: bytes, limit: int = MAX_FILE_BYTES) -> str:
    """Decode an input file as UTF-8 (a leading UTF-8 byte-order mark is dropped) and screen it
    (:func:`screen_text`, at most ``limit`` characters).

    Raises:
        TextProblem: a UTF-16/UTF-32 byte-order mark, bytes that are not UTF-8, NUL bytes, with
            the line of the first offending byte.
    """
    for bom, name in _BOMS:
        if data.startswith(bom):
            raise TextProblem(f"not UTF-8 text: the file starts with a {name} byte-order mark "
                              "(save it as UTF-8)", 1)
    data = data.removeprefix(_UTF8_BOM)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line, col = _line_col(data, exc.start)
        raise TextProblem(f"not UTF-8 text: byte 0x{data[exc.start]:02x} at column {col} "
                          "(a binary file, or another encoding?)", line) from None
    screen_text(text, limit)
    return text


def screen_text(text: str, limit: int = MAX_FILE_BYTES) -> None:
    """Refuse text that no input file may hold: NUL characters, lone surrogates, over ``limit`` chars.

    Raises:
        TextProblem: with the line of the first offending character.
    """
    if len(text) > limit:
        raise TextProblem(f"text too large: {len(text)} characters (the limit is {size_text(limit)})", 1)
    nul = text.find("\0")
    if nul >= 0:
        head = text[:4096]
        if head.count("\0") * 4 >= len(head):
            raise TextProblem("not UTF-8 text: NUL bytes throughout (UTF-16 without a byte-order mark, "
                              "or a binary file?)", 1)
        line, col = _line_col(text, nul)
        raise TextProblem(f"NUL character at column {col}: input files are text without NUL", line)
    try:
        text.encode("utf-8")
    except UnicodeEncodeError as exc:
        line, col = _line_col(text, exc.start)
        raise TextProblem(f"not UTF-8 text: lone surrogate at column {col}", line) from None


def write_atomically(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` through a temporary file in the same directory, renamed over it.

    Raises:
        OSError: the file cannot be written; ``path`` is then unchanged and no temporary file remains.
    """
    target = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
