"""The shared key (services.keys)."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from services.keys import (
    MIN_KEY_BYTES,
    SharedKeyError,
    check_key,
    decode_key,
    load_key,
    load_keys,
)

PASSPHRASE = "correct horse battery staple"


def private_file(path: Path, text: str, mode: int = 0o600) -> Path:
    path.write_text(text)
    path.chmod(mode)
    return path


def test_hex_keys_are_decoded_and_other_text_is_taken_as_is() -> None:
    assert decode_key("ab" * 16) == bytes([0xAB]) * 16
    assert decode_key(f"  {PASSPHRASE} \n") == PASSPHRASE.encode()
    with pytest.raises(SharedKeyError):
        decode_key("  \n")


def test_a_key_shorter_than_16_bytes_is_refused_with_a_way_to_make_one() -> None:
    with pytest.raises(SharedKeyError, match="1 bytes; at least 16") as err:
        decode_key("x")
    assert "secrets.token_hex" in str(err.value)
    with pytest.raises(SharedKeyError, match="15 bytes"):
        check_key(b"k" * 15)
    assert check_key(b"k" * MIN_KEY_BYTES) == b"k" * 16
    assert decode_key("ab" * 8) == b"ab" * 8  # 16 hex digits are too few to be hex: 16 bytes of text


def test_env_key_wins_over_the_default_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PETROBOT_KEY", PASSPHRASE)
    monkeypatch.setenv("PETROBOT_KEY_FILE", str(tmp_path / "unused"))
    assert load_key() == PASSPHRASE.encode()
    assert not (tmp_path / "unused").exists()


def test_a_short_key_in_the_environment_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PETROBOT_KEY", "hunter2")
    with pytest.raises(SharedKeyError, match="PETROBOT_KEY is 7 bytes"):
        load_key()


def test_an_explicit_key_file_wins_over_the_env(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PETROBOT_KEY", PASSPHRASE)
    f = private_file(tmp_path / "key", "cd" * 32 + "\n")
    assert load_key(f) == bytes([0xCD]) * 32


@pytest.mark.parametrize("mode", [0o620, 0o602, 0o666])
def test_a_key_file_others_can_write_is_refused(tmp_path: Path, mode: int) -> None:
    f = private_file(tmp_path / "key", "cd" * 32, mode)
    with pytest.raises(SharedKeyError, match=f"writable by other users \\(mode {mode:04o}\\); run: chmod 600"):
        load_key(f)


def test_a_key_file_others_can_read_is_used_with_a_warning(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    f = private_file(tmp_path / "key", "cd" * 32, 0o644)
    assert load_key(f) == bytes([0xCD]) * 32
    assert "readable by other users" in caplog.text and "chmod 600" in caplog.text


def test_a_key_file_with_a_short_key_is_refused_naming_the_line(tmp_path: Path) -> None:
    f = private_file(tmp_path / "key", "cd" * 32 + "\n\nshort\n")
    with pytest.raises(SharedKeyError, match="key on line 3 is 5 bytes"):
        load_keys(f)


def test_the_lines_after_the_first_are_previous_keys_for_rotation(tmp_path: Path) -> None:
    f = private_file(tmp_path / "key", "ab" * 32 + "\n\n" + "cd" * 32 + "\n" + PASSPHRASE + "\n")
    assert load_keys(f) == (bytes([0xAB]) * 32, bytes([0xCD]) * 32, PASSPHRASE.encode())
    assert load_key(f) == bytes([0xAB]) * 32  # a client connects with the first


def test_a_missing_key_file_is_created_private_and_reused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("PETROBOT_KEY", raising=False)
    path = tmp_path / "sub" / "key"
    monkeypatch.setenv("PETROBOT_KEY_FILE", str(path))
    key = load_key()
    assert len(key) == 32
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
    assert load_key() == key


def test_a_missing_key_file_is_an_error_when_creation_is_off(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("PETROBOT_KEY", raising=False)
    with pytest.raises(SharedKeyError, match="does not exist"):
        load_key(tmp_path / "none", create=False)
