"""The platform's foreign libraries built on first use (native_library.pl), as an installed
wheel meets them: a copy of platform_pl/ holding the C sources only, real swipl and swipl-ld
processes, a cache folder made here.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

from dfrl.platform_pl import PLATFORM_DIR

from .conftest import SWIPL

pytestmark = pytest.mark.skipif(
    SWIPL is None or shutil.which("swipl-ld") is None, reason="swipl or swipl-ld missing"
)

#: Each foreign library and the predicate saying whether it is loaded.
LIBRARIES = {
    "float_vectors": "float_vectors_native",
    "bulk_write": "bulk_write_native",
    "fast_term_check": "fast_term_check_native",
    "tls": "tls_direct_native",
}


def _sources_only(tmp: Path) -> Path:
    platform = tmp / "platform_pl"
    shutil.copytree(PLATFORM_DIR, platform, ignore=shutil.ignore_patterns("*.so", "*.tmp"))
    return platform


def _load_all(platform: Path, cache: Path, path: str | None = None) -> subprocess.CompletedProcess:
    goal = ", ".join(
        [f"use_module('{platform / m}')" for m in LIBRARIES]
        + [f"{p}(B{i}), writeln({p}=B{i})" for i, p in enumerate(LIBRARIES.values())]
        + ["halt"]
    )
    env = {**os.environ, "DFRL_NATIVE_CACHE": str(cache)}
    if path is not None:
        env["PATH"] = path
    assert SWIPL
    return subprocess.run(
        [SWIPL, "-q", "-g", goal], capture_output=True, text=True, timeout=120, env=env
    )


def test_sources_only_are_built_once_into_the_cache(tmp_path: Path) -> None:
    platform, cache = _sources_only(tmp_path), tmp_path / "cache"
    first = _load_all(platform, cache)
    assert first.returncode == 0, first.stderr
    for pred in LIBRARIES.values():
        assert f"{pred}=true" in first.stdout, first.stdout + first.stderr
    built = sorted(cache.rglob("*.so"))
    assert len(built) == 4, built
    assert not list(platform.rglob("*.so")), "nothing is written beside the sources"
    stamps = [p.stat().st_mtime_ns for p in built]
    second = _load_all(platform, cache)
    assert second.returncode == 0 and "=false" not in second.stdout, second.stderr
    assert [p.stat().st_mtime_ns for p in built] == stamps, "a second start rebuilt"


def test_a_changed_source_gets_its_own_build(tmp_path: Path) -> None:
    platform, cache = _sources_only(tmp_path), tmp_path / "cache"
    assert _load_all(platform, cache).returncode == 0
    source = platform / "native" / "bulk_write.c"
    source.write_text(source.read_text() + "\n/* changed */\n")
    run = _load_all(platform, cache)
    assert "bulk_write_native=true" in run.stdout, run.stderr
    assert len(list(cache.rglob("bulk_write.so"))) == 2


def test_without_a_compiler_the_platform_says_so_and_runs_its_prolog(tmp_path: Path) -> None:
    platform, cache = _sources_only(tmp_path), tmp_path / "cache"
    run = _load_all(platform, cache, path=str(tmp_path / "empty"))
    assert run.returncode == 0, run.stderr
    for pred in LIBRARIES.values():
        assert f"{pred}=false" in run.stdout, run.stdout
    assert "the foreign library float_vectors is not used" in run.stderr, run.stderr
    assert "swipl-ld" in run.stderr, run.stderr
    assert not list(cache.rglob("*.so"))


def test_a_source_that_does_not_compile_is_reported_with_the_compiler_output(
    tmp_path: Path,
) -> None:
    platform, cache = _sources_only(tmp_path), tmp_path / "cache"
    (platform / "native" / "bulk_write.c").write_text("int broken(\n")
    run = _load_all(platform, cache)
    assert "bulk_write_native=false" in run.stdout, run.stdout
    assert "float_vectors_native=true" in run.stdout, run.stdout
    assert "cannot build" in run.stderr and "bulk_write.c" in run.stderr, run.stderr
    assert "error" in run.stderr
    assert not list(cache.rglob("*.tmp")), "the failed build's temporary file is removed"
