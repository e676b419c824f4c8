"""The shared key (services.keys)."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from services.keys import SharedKeyError, decode_key, load_key


def test_hex_keys_are_decoded_and_other_text_is_taken_as_is() -> None:
    assert decode_key("ab" * 16) == bytes([0xAB]) * 16
    assert decode_key("  secret words \n") == b"secret words"
    with pytest.raises(SharedKeyError):
        decode_key("  \n")


def test_env_key_wins_over_the_default_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PETROBOT_KEY", "hunter2")
    monkeypatch.setenv("PETROBOT_KEY_FILE", str(tmp_path / "unused"))
    assert load_key() == b"hunter2"
    assert not (tmp_path / "unused").exists()


def test_an_explicit_key_file_wins_over_the_env(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PETROBOT_KEY", "hunter2")
    f = tmp_path / "key"
    f.write_text("cd" * 32 + "\n")
    assert load_key(f) == bytes([0xCD]) * 32


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
