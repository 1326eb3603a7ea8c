"""The JIT build: cache keyed by the sources, clear errors on compiler failure, CPU ISA detection."""

from __future__ import annotations

import pytest

from eigs.errors import EigsError
from eigs.render import _backend


def test_build_failure_names_the_compiler_error(tmp_path, monkeypatch) -> None:
    src = tmp_path / "csrc"
    src.mkdir()
    (src / "broken.cpp").write_text("int f() { return undeclared_symbol_xyz; }\n")
    monkeypatch.setenv("EIGS_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(_backend, "CSRC", src)
    monkeypatch.setattr(_backend, "SOURCES", ("broken.cpp",))
    monkeypatch.setattr(_backend, "HEADERS", ())
    monkeypatch.setattr(_backend, "_module", None)
    with pytest.raises(EigsError) as exc:
        _backend.load()
    msg = str(exc.value)
    assert "building the C++ rasterizer failed" in msg
    assert "undeclared_symbol_xyz" in msg and "error" in msg
    assert str(src) in msg


def test_cache_key_follows_the_sources(tmp_path, monkeypatch) -> None:
    src = tmp_path / "csrc"
    src.mkdir()
    for name in _backend.SOURCES + _backend.HEADERS:
        (src / name).write_bytes((_backend.CSRC / name).read_bytes())
    monkeypatch.setattr(_backend, "CSRC", src)
    before = _backend.source_hash()
    assert before == _backend.source_hash()
    (src / "pair_math.h").write_text((src / "pair_math.h").read_text() + "\n// edit\n")
    assert _backend.source_hash() != before
    monkeypatch.setenv("EIGS_CACHE_DIR", str(tmp_path / "c"))
    assert _backend.cache_dir() == tmp_path / "c"


def test_two_checkouts_do_not_share_a_build(tmp_path, monkeypatch) -> None:
    """The same sources in two folders get two builds: one shared build file would name one folder's sources and the
    other checkout's every load would rebuild it."""
    hashes = []
    for checkout in ("a", "b"):
        src = tmp_path / checkout / "csrc"
        src.mkdir(parents=True)
        for name in _backend.SOURCES + _backend.HEADERS:
            (src / name).write_bytes((_backend.CSRC / name).read_bytes())
        monkeypatch.setattr(_backend, "CSRC", src)
        hashes.append(_backend.source_hash())
    assert hashes[0] != hashes[1]


def test_isa_detection() -> None:
    isas = _backend.available_isas()
    assert isas[0] == "baseline" and set(isas) <= {"baseline", "avx2", "avx512"}
    with open("/proc/cpuinfo") as f:
        flags = f.read()
    assert ("avx2" in isas) == (" avx2" in flags and " fma" in flags)
    with pytest.raises(ValueError, match="isa"):
        _backend.isa_code("sse9")


def test_every_csrc_file_is_built_and_hashed() -> None:
    # A header missing from HEADERS would not enter the cache key: editing it would load a stale build.
    on_disk = {p.name for p in _backend.CSRC.iterdir() if p.suffix in (".cpp", ".h", ".inc")}
    assert on_disk == set(_backend.SOURCES + _backend.HEADERS)


def test_a_stale_build_lock_is_removed(tmp_path) -> None:
    """PyTorch's ``lock`` file left in the build folder by a process killed while loading (SIGKILL: no cleanup) does
    not make the next load wait for ever: the load removes it and returns. On a private copy of the built extension
    (``EIGS_CACHE_DIR``, times kept so the build stays up to date): in the shared cache another test's load may
    remove the file first."""
    import os
    import shutil
    import subprocess
    import sys

    from eigs.util.cache import ENV

    _backend.load()  # built and up to date
    name = f"eigs_render_{_backend.source_hash()}"
    build = tmp_path / "torch_extensions" / name
    shutil.copytree(_backend.cache_dir() / "torch_extensions" / name, build, ignore=shutil.ignore_patterns("lock"))
    env = {**os.environ, ENV: str(tmp_path)}
    held = subprocess.Popen([sys.executable, "-c", (
        "import fcntl, pathlib, sys, time\n"
        f"b = pathlib.Path({str(build)!r})\n"
        "fh = open(b / '.eigs_load.lock', 'a'); fcntl.flock(fh, fcntl.LOCK_EX)\n"
        "(b / 'lock').touch()\n"
        "import os, signal; os.kill(os.getpid(), signal.SIGKILL)\n")])  # fmt: skip
    assert held.wait(timeout=60) == -9
    assert (build / "lock").exists()
    proc = subprocess.run([sys.executable, "-c", "from eigs.render._backend import load; load()"], env=env,
                          capture_output=True, text=True, timeout=300, check=False)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "left by a process that died" in proc.stderr
    assert not (build / "lock").exists()


def test_no_float32_kernel_expands_its_lane_vectors_piecewise(tmp_path) -> None:
    """GCC expands a lane-vector comparison or select lane by lane when the function that holds it lacks the
    kernel's target attribute, even once inlined into the AVX-512 kernel (pair_lanes.inc): that made the AVX-512
    backward 4-6x slower than the AVX2 one without changing a bit of its output, so only the compiler can tell.
    Compiles the compositing kernels with the extension's flags and ``-Wvector-operation-performance``: no such
    warning may come from a float32 kernel (the float64 one, the gradcheck path, is exempt)."""
    import shutil
    import subprocess

    cxx = shutil.which("g++") or shutil.which("c++")
    if cxx is None:
        pytest.skip("no C++ compiler")
    for src in ("rasterize_bwd.cpp", "rasterize_fwd.cpp"):
        out = subprocess.run([cxx, "-std=c++20", *_backend.CFLAGS, "-Wvector-operation-performance",
                              f"-I{_backend.CSRC}", "-c", str(_backend.CSRC / src), "-o", str(tmp_path / "k.o")],
                             capture_output=True, text=True)  # fmt: skip
        assert out.returncode == 0, out.stderr[-2000:]
        # each warning names the kernel it was inlined into: "inlined from 'void ...bwd_f32_c3_avx512(...)'"
        piecewise = [line for line in out.stderr.splitlines() if "inlined from" in line and "_f32_" in line]
        assert not piecewise, f"{src}:\n" + "\n".join(piecewise[:10])
