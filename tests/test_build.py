"""The import-time CPU check: the features recorded in the extension against the host's, on fabricated inputs."""

import pytest

import legkit
from legkit import _build, _core
from legkit._build import CPUINFO_NAMES, compiled_features, missing_cpu_features

# What Rust 1.95 records for -C target-cpu=x86-64-v3 (CARGO_CFG_TARGET_FEATURE, in its order).
X86_64_V3 = "avx,avx2,bmi1,bmi2,cmpxchg16b,f16c,fma,fxsr,lzcnt,movbe,popcnt,sse,sse2,sse3,sse4.1,sse4.2,ssse3,xsave".split(",")
# Sandy Bridge's /proc/cpuinfo flags: AVX but no AVX2, BMI, FMA, F16C, LZCNT (abm) or MOVBE.
SANDY_BRIDGE = "fpu vme de pse tsc msr pae mce cx8 apic sep mtrr pge mca cmov pat pse36 clflush mmx fxsr sse sse2 ss ht syscall nx lm " \
    "constant_tsc pni pclmulqdq ssse3 cx16 sse4_1 sse4_2 x2apic popcnt aes xsave avx lahf_lm"


def cpuinfo(flags: str) -> str:
    return f"processor\t: 0\nvendor_id\t: GenuineIntel\nflags\t\t: {flags}\nbugs\t\t: spectre_v1\n"


def test_a_cpu_with_every_compiled_feature_misses_none() -> None:
    flags = " ".join(CPUINFO_NAMES[f] for f in X86_64_V3)
    assert missing_cpu_features(X86_64_V3, cpuinfo(flags)) == []


def test_an_older_cpu_misses_the_v3_features_in_the_records_order() -> None:
    assert missing_cpu_features(X86_64_V3, cpuinfo(SANDY_BRIDGE)) == ["avx2", "bmi1", "bmi2", "f16c", "fma", "lzcnt", "movbe"]


def test_a_native_build_on_the_older_cpu_passes() -> None:
    # What target-cpu=native records on Sandy Bridge: only what the CPU has (and names cpuinfo spells otherwise).
    native = "aes,avx,cmpxchg16b,fxsr,lahfsahf,pclmulqdq,popcnt,sse,sse2,sse3,sse4.1,sse4.2,ssse3,x87,xsave".split(",")
    assert missing_cpu_features(native, cpuinfo(SANDY_BRIDGE + " fpu")) == []


def test_features_without_a_known_cpuinfo_name_are_not_refused() -> None:
    assert missing_cpu_features(["crt-static", "prfchw", "avx2"], cpuinfo("sse sse2")) == ["avx2"]


def test_no_flags_line_checks_nothing() -> None:
    assert missing_cpu_features(X86_64_V3, "processor : 0\nFeatures : fp asimd\n") == []


def test_the_record_is_read_from_the_library_bytes() -> None:
    assert compiled_features(b"\x00junk" + _build.MARKER + b"avx,avx2,sse4.1;\x00more") == ["avx", "avx2", "sse4.1"]
    assert compiled_features(_build.MARKER + b";") == []
    assert compiled_features(b"an extension from before the record") is None


def test_the_installed_extension_records_what_it_exports() -> None:
    recorded = _build._extension_features()
    assert recorded is not None and recorded == _core.COMPILED_TARGET_FEATURES.split(",")


def test_check_cpu_names_the_missing_features(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_build, "_extension_features", lambda: X86_64_V3)
    monkeypatch.setattr(_build.platform, "machine", lambda: "x86_64")
    monkeypatch.setattr(_build.sys, "platform", "linux")
    real_open = open

    def fake_open(path, *args, **kwargs):  # type: ignore[no-untyped-def]
        if path == "/proc/cpuinfo":
            import io

            return io.StringIO(cpuinfo(SANDY_BRIDGE))
        return real_open(path, *args, **kwargs)

    monkeypatch.setattr("builtins.open", fake_open)
    with pytest.raises(ImportError, match=r"lacks: avx2, bmi1, bmi2, f16c, fma, lzcnt, movbe\. .*target-cpu=native"):
        _build.check_cpu()
    assert legkit.aba is not None
