"""Signing keys and key files: the 32-byte secret (never shown), reading and writing key
files, where a verifier keeps its streams beside the key file, and the key-file command
line (``python -m interfaces.mavlink.signing``). The policy: interfaces/mavlink/README.md,
"Signing: keys, clocks and replay"."""
from __future__ import annotations

import hashlib
import hmac
import logging
import os
import secrets
import stat
import string
from pathlib import Path

log = logging.getLogger(__name__)

KEY_ENV = "ELLIPSLED_SIGNING_KEY_FILE"
KEY_LEN_BYTES = 32
KEY_HEX_CHARS = 2 * KEY_LEN_BYTES
_KEY_FILE_MAX_BYTES = 4096

_SRC_TREE = Path(__file__).resolve().parents[3]
REPO_ROOT: Path | None = (_SRC_TREE if (_SRC_TREE / "pyproject.toml").is_file()
                          or (_SRC_TREE / ".git").exists() else None)


class SigningKeyError(ValueError):
    """A signing key could not be loaded; the message names the file, never its content."""


class SigningKey:
    """A 32-byte MAVLink signing secret. ``repr`` shows only the source and ``key_id``."""

    __slots__ = ("_secret", "source", "path")

    def __init__(self, secret: bytes, source: str = "<memory>"):
        if not isinstance(secret, (bytes, bytearray)) or len(secret) != KEY_LEN_BYTES:
            raise SigningKeyError(f"signing key from {source}: must be {KEY_LEN_BYTES} bytes")
        self._secret = bytes(secret)
        self.source = source
        self.path: Path | None = None       # the key file it was read from, if any

    @property
    def secret(self) -> bytes:
        return self._secret

    @property
    def key_id(self) -> str:
        """8 hex digits of a domain-separated SHA-256 of the key (cannot reveal it)."""
        return hashlib.sha256(b"ellipsled-signing-key-id\0" + self._secret).hexdigest()[:8]

    def __repr__(self) -> str:
        return f"SigningKey(source={self.source!r}, key_id={self.key_id})"

    __str__ = __repr__

    def __eq__(self, other: object) -> bool:
        return isinstance(other, SigningKey) and hmac.compare_digest(self._secret, other._secret)

    __hash__ = None  # type: ignore[assignment]

    @classmethod
    def generate(cls) -> "SigningKey":
        return cls(secrets.token_bytes(KEY_LEN_BYTES), "<generated>")

    @classmethod
    def from_hex(cls, text: str, source: str = "<memory>") -> "SigningKey":
        s = text.strip()
        if len(s) != KEY_HEX_CHARS:
            raise SigningKeyError(f"signing key from {source}: expected {KEY_HEX_CHARS} hex "
                                  f"characters ({KEY_LEN_BYTES} bytes), found {len(s)} characters")
        if not all(c in string.hexdigits for c in s):
            raise SigningKeyError(f"signing key from {source}: contains characters that are "
                                  f"not hexadecimal digits")
        return cls(bytes.fromhex(s), source)

    @classmethod
    def from_file(cls, path: str | os.PathLike[str] | None = None, *,
                  env: dict[str, str] | os._Environ[str] | None = None) -> "SigningKey":
        """Load from ``path``, else from the file named by $ELLIPSLED_SIGNING_KEY_FILE."""
        if path is None:
            path = (os.environ if env is None else env).get(KEY_ENV) or None
            if path is None:
                raise SigningKeyError(f"no signing key: pass a key file path or set {KEY_ENV}")
        p = Path(path).expanduser()
        _refuse_inside_repo(p)
        try:
            st = p.stat()
            if not stat.S_ISREG(st.st_mode):
                raise SigningKeyError(f"signing key file {p}: not a regular file")
            if st.st_size > _KEY_FILE_MAX_BYTES:
                raise SigningKeyError(f"signing key file {p}: too large ({st.st_size} bytes) "
                                      f"for a {KEY_HEX_CHARS}-character key")
            raw = p.read_bytes()[:_KEY_FILE_MAX_BYTES]
        except FileNotFoundError:
            raise SigningKeyError(f"signing key file not found: {p}") from None
        except PermissionError:
            raise SigningKeyError(f"signing key file {p}: permission denied") from None
        except IsADirectoryError:
            raise SigningKeyError(f"signing key file {p}: is a directory") from None
        except OSError as e:
            raise SigningKeyError(f"signing key file {p}: cannot read ({e.strerror})") from None
        if st.st_mode & 0o077:
            log.warning("signing key file %s is readable by group/others; chmod 600 it", p)
        try:
            text = raw.decode("ascii")
        except UnicodeDecodeError:
            raise SigningKeyError(f"signing key from {p}: contains characters that are not "
                                  f"hexadecimal digits") from None
        key = cls.from_hex(text, str(p))
        key.path = p
        return key

    def write_file(self, path: str | os.PathLike[str]) -> Path:
        """Write as 64 hex characters + newline, mode 0600; refuses to overwrite or to
        write inside the repository."""
        p = Path(path).expanduser()
        _refuse_inside_repo(p)
        try:
            fd = os.open(p, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        except FileExistsError:
            raise SigningKeyError(f"signing key file {p}: already exists") from None
        with os.fdopen(fd, "w", encoding="ascii") as f:
            f.write(self._secret.hex() + "\n")
        return p


def stream_state_path(key: SigningKey) -> Path | None:
    """Where a verifier using ``key`` keeps its streams' last timestamps: beside the key
    file (its name + ``.streams``); None for a key that did not come from a file."""
    return None if key.path is None else key.path.with_name(key.path.name + ".streams")


def _refuse_inside_repo(p: Path) -> None:
    if REPO_ROOT is None:
        return
    resolved = p.resolve()
    if resolved.is_relative_to(REPO_ROOT):
        raise SigningKeyError(f"signing key file {p} is inside the repository tree "
                              f"({REPO_ROOT}); keep keys outside it so they are never committed")


def main(argv: list[str] | None = None) -> int:
    """``python -m interfaces.mavlink.signing new-key PATH``: write a fresh key file (0600)."""
    import argparse
    ap = argparse.ArgumentParser(description="ellipsled MAVLink signing keys")
    sub = ap.add_subparsers(dest="cmd", required=True)
    nk = sub.add_parser("new-key", help="write a new random key file (mode 0600, must not exist)")
    nk.add_argument("path", type=Path)
    ck = sub.add_parser("check-key", help="load a key file and print its key id")
    ck.add_argument("path", type=Path, nargs="?")
    args = ap.parse_args(argv)
    try:
        if args.cmd == "new-key":
            key = SigningKey.generate()
            p = key.write_file(args.path)
            print(f"wrote {p} (key id {key.key_id})")
        else:
            key = SigningKey.from_file(args.path)
            print(f"{key.source}: key id {key.key_id}")
    except SigningKeyError as e:
        print(f"error: {e}")
        return 1
    return 0
