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
KEY_A = "7f3d91c4e0a2b8561de47c93f0a6b2158e4d7a03c9f1b6e25d80a4c7f39e1b62"
KEY_B = "c05e8a2f71d493b6e8f2a07d5c19b3e4a6d0f7285b1c9e3da4f6071e82c5b9d3"


def private_file(path: Path, text: str, mode: int = 0o600) -> Path:
    path.write_text(text)
    path.chmod(mode)
    return path


def test_hex_keys_are_decoded_and_other_text_is_taken_as_is() -> None:
    assert decode_key("7f3d91c4e0a2b8561de47c93f0a6b215") == bytes.fromhex("7f3d91c4e0a2b8561de47c93f0a6b215")
    assert decode_key(f"  {PASSPHRASE} \n") == PASSPHRASE.encode()
    with pytest.raises(SharedKeyError):
        decode_key("  \n")


def test_a_key_shorter_than_16_bytes_is_refused_with_a_way_to_make_one() -> None:
    with pytest.raises(SharedKeyError, match="1 bytes; at least 16") as err:
        decode_key("x")
    assert "secrets.token_hex" in str(err.value)
    with pytest.raises(SharedKeyError, match="15 bytes"):
        check_key(b"k" * 15)
    assert check_key(bytes.fromhex("7f3d91c4e0a2b8561de47c93f0a6b215")) == bytes.fromhex("7f3d91c4e0a2b8561de47c93f0a6b215")
    assert decode_key("7f3d91c4e0a2b856") == b"7f3d91c4e0a2b856"  # 16 hex digits are too few to be hex: 16 bytes of text


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
    f = private_file(tmp_path / "key", KEY_B + "\n")
    assert load_key(f) == bytes.fromhex(KEY_B)


@pytest.mark.parametrize("mode", [0o620, 0o602, 0o666])
def test_a_key_file_others_can_write_is_refused(tmp_path: Path, mode: int) -> None:
    f = private_file(tmp_path / "key", KEY_B, mode)
    with pytest.raises(SharedKeyError, match=f"writable by other users \\(mode {mode:04o}\\); run: chmod 600"):
        load_key(f)


def test_a_key_file_others_can_read_is_used_with_a_warning(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    f = private_file(tmp_path / "key", KEY_B, 0o644)
    assert load_key(f) == bytes.fromhex(KEY_B)
    assert "readable by other users" in caplog.text and "chmod 600" in caplog.text


def test_a_key_file_with_a_short_key_is_refused_naming_the_line(tmp_path: Path) -> None:
    f = private_file(tmp_path / "key", KEY_B + "\n\nshort\n")
    with pytest.raises(SharedKeyError, match="key on line 3 is 5 bytes"):
        load_keys(f)


def test_the_lines_after_the_first_are_previous_keys_for_rotation(tmp_path: Path) -> None:
    f = private_file(tmp_path / "key", KEY_A + "\n\n" + KEY_B + "\n" + PASSPHRASE + "\n")
    assert load_keys(f) == (bytes.fromhex(KEY_A), bytes.fromhex(KEY_B), PASSPHRASE.encode())
    assert load_key(f) == bytes.fromhex(KEY_A)  # a client connects with the first


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


@pytest.mark.parametrize("key, why", [
    (bytes(16), "repeats a pattern of 1 byte"),
    ("00" * 32, "repeats a pattern of 1 byte"),
    ("passwordpassword", "repeats a pattern of 8 bytes"),
    (bytes(range(32)), "constant steps"),
    ("0123456789abcdef", "constant steps"),
    (bytes([1, 7, 1, 3, 7, 5, 1, 3, 5, 7, 3, 1, 5, 7, 3, 5]), "take 4 values"),
])
def test_a_weak_key_is_refused_as_a_short_one_is(key: bytes | str, why: str) -> None:
    """Issue 22: a key of 16 zero bytes was accepted."""
    with pytest.raises(SharedKeyError, match=f"weak: .*{why}") as err:
        decode_key(key) if isinstance(key, str) else check_key(key)
    assert "secrets.token_hex" in str(err.value)


def test_random_keys_and_a_passphrase_are_not_weak() -> None:
    for _ in range(2000):
        check_key(os.urandom(MIN_KEY_BYTES))
    assert decode_key(PASSPHRASE) == PASSPHRASE.encode()


def test_a_node_refuses_a_weak_key_given_in_code(tmp_path: Path) -> None:
    from services.location import parse_location
    from services.node import Node

    location = parse_location('[nodes.alpha]\nhost = "127.0.0.1"\nport = 7\n')
    with pytest.raises(SharedKeyError, match="weak"):
        Node("alpha", location, bytes(32))
