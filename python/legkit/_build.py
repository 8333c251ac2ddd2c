"""The CPU features the compiled extension needs, checked before it loads.

The extension records the target features it was compiled with (crates/pybind/build.rs: x86-64-v3 from
``.cargo/config.toml`` by default, whatever ``RUSTFLAGS='-C target-cpu=...'`` gives otherwise) behind a marker
in the library's bytes. On x86-64 Linux, importing legkit reads that record without loading the library and
compares it with the CPU's flags in /proc/cpuinfo: a CPU that lacks one would stop on an illegal instruction
inside ``legkit._core``, so the import fails first, naming the features. A rebuild for the machine itself
(``target-cpu=native``) records exactly the features it has, and imports."""

from __future__ import annotations

import importlib.util
import mmap
import platform
import sys
from collections.abc import Iterable

MARKER = b"legkit-target-features="

# Rust's x86 target-feature names (CARGO_CFG_TARGET_FEATURE) as /proc/cpuinfo spells them. Only the features of
# this table are checked: a name whose cpuinfo spelling is not known here is skipped rather than refused, so
# that a native build never fails on its own machine over a spelling.
CPUINFO_NAMES = {
    **{name: name for name in (
        "adx", "aes", "avx", "avx2", "avx512bw", "avx512cd", "avx512dq", "avx512f", "avx512ifma", "avx512vbmi", "avx512vl", "bmi1",
        "bmi2", "f16c", "fma", "fxsr", "gfni", "movbe", "pclmulqdq", "popcnt", "rdrand", "rdseed", "rtm", "sse", "sse2", "sse4a",
        "ssse3", "tbm", "vaes", "vpclmulqdq", "xsave", "xsavec", "xsaveopt", "xsaves",
    )},
    "avx512bf16": "avx512_bf16", "avx512bitalg": "avx512_bitalg", "avx512fp16": "avx512_fp16", "avx512vbmi2": "avx512_vbmi2",
    "avx512vnni": "avx512_vnni", "avx512vp2intersect": "avx512_vp2intersect", "avx512vpopcntdq": "avx512_vpopcntdq",
    "avxvnni": "avx_vnni", "cmpxchg16b": "cx16", "ermsb": "erms", "lahfsahf": "lahf_lm", "lzcnt": "abm", "sha": "sha_ni",
    "sse3": "pni", "sse4.1": "sse4_1", "sse4.2": "sse4_2", "x87": "fpu",
}


def compiled_features(library: bytes | mmap.mmap) -> list[str] | None:
    """The target features recorded in a compiled extension's bytes, or None if it holds no record (a build
    from before the record existed)."""
    start = library.find(MARKER)
    if start < 0:
        return None
    start += len(MARKER)
    end = library.find(b";", start)
    return [f for f in bytes(library[start:end]).decode("ascii", "replace").split(",") if f]


def cpu_flags(cpuinfo: str) -> set[str] | None:
    """The flags of the first ``flags`` line of ``cpuinfo`` (/proc/cpuinfo's text), None if it has none."""
    for line in cpuinfo.splitlines():
        if line.startswith("flags"):
            return set(line.partition(":")[2].split())
    return None


def missing_cpu_features(compiled: Iterable[str], cpuinfo: str) -> list[str]:
    """The features of ``compiled`` (Rust's names, in their order) that the CPU described by ``cpuinfo`` lacks."""
    flags = cpu_flags(cpuinfo)
    if flags is None:
        return []
    return [f for f in compiled if f in CPUINFO_NAMES and CPUINFO_NAMES[f] not in flags]


def _extension_features() -> list[str] | None:
    spec = importlib.util.find_spec("legkit._core")
    if spec is None or not spec.origin:
        return None
    with open(spec.origin, "rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as library:
        return compiled_features(library)


def check_cpu() -> None:
    """Raises ImportError on an x86-64 Linux CPU that lacks a feature the installed extension was compiled for."""
    if not (sys.platform.startswith("linux") and platform.machine() in ("x86_64", "AMD64")):
        return
    try:
        compiled = _extension_features()
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            cpuinfo = f.read()
    except (OSError, ValueError):  # unreadable: the loader reports a missing or broken library itself
        return
    missing = missing_cpu_features(compiled or [], cpuinfo)
    if missing:
        raise ImportError(
            f"legkit's extension was compiled for CPU features this CPU lacks: {', '.join(missing)}. Rebuild it for this machine "
            "from the legkit checkout: RUSTFLAGS='-C target-cpu=native' .venv/bin/pip install ."
        )


check_cpu()
