"""The CPU the compiled extension needs, checked before it loads.

On x86-64 Linux the extension is built for x86-64-v3 (``.cargo/config.toml``): a CPU without these features
would stop on an illegal instruction inside ``legkit._core``, so importing legkit fails first, naming them."""

from __future__ import annotations

import platform
import sys

# The x86-64-v3 features beyond baseline x86-64 (v2 and v3), as /proc/cpuinfo spells them.
X86_64_V3_FLAGS = ("cx16", "lahf_lm", "popcnt", "sse4_1", "sse4_2", "ssse3", "avx", "avx2", "bmi1", "bmi2", "f16c", "fma", "abm", "movbe", "xsave")


def missing_cpu_features(cpuinfo: str) -> list[str]:
    """The x86-64-v3 features absent from the first ``flags`` line of ``cpuinfo`` (/proc/cpuinfo's text)."""
    for line in cpuinfo.splitlines():
        if line.startswith("flags"):
            present = set(line.partition(":")[2].split())
            return [flag for flag in X86_64_V3_FLAGS if flag not in present]
    return []


def check_cpu() -> None:
    """Raises ImportError on an x86-64 Linux CPU that lacks a feature the extension was built for."""
    if not (sys.platform.startswith("linux") and platform.machine() in ("x86_64", "AMD64")):
        return
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            cpuinfo = f.read()
    except OSError:
        return
    missing = missing_cpu_features(cpuinfo)
    if missing:
        raise ImportError(
            f"legkit's extension is built for x86-64-v3 CPUs (Intel Haswell, AMD Zen and later); this CPU lacks {', '.join(missing)}. "
            "Build it for this machine with RUSTFLAGS='-C target-cpu=native' pip install ."
        )


check_cpu()
