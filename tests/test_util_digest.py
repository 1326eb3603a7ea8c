"""eigs.util.digest.files_digest against hashlib over the same bytes, and what changes it."""

from __future__ import annotations

import hashlib

from eigs.util.digest import CHUNK, files_digest


def test_digest_is_sha256_of_names_and_bytes(tmp_path):
    big = bytes(range(256)) * (CHUNK // 256 + 3)  # spans several reads
    (tmp_path / "a.bin").write_bytes(big)
    d = tmp_path / "model"
    (d / "sub").mkdir(parents=True)
    (d / "z.txt").write_bytes(b"z")
    (d / "sub" / "b.txt").write_bytes(b"b")
    expected = hashlib.sha256(
        b"\0input\0init\0" + big + b"\0input\0sfm\0" + b"\0file\0sub/b.txt\0b" + b"\0file\0z.txt\0z"
        + b"\0input\0zzz\0\0missing\0"
    ).hexdigest()  # fmt: skip
    assert files_digest({"sfm": d, "init": tmp_path / "a.bin", "zzz": tmp_path / "absent"}) == expected


def test_digest_changes_with_a_byte_a_name_or_a_file(tmp_path):
    (tmp_path / "x").write_bytes(b"0123")
    base = files_digest({"init": tmp_path / "x"})
    assert files_digest({"init": tmp_path / "x"}) == base  # deterministic
    assert files_digest({"edi": tmp_path / "x"}) != base  # another input name
    (tmp_path / "x").write_bytes(b"0124")
    assert files_digest({"init": tmp_path / "x"}) != base
    (tmp_path / "x").unlink()
    assert files_digest({"init": tmp_path / "x"}) != base
    assert files_digest({}) == hashlib.sha256(b"").hexdigest()
