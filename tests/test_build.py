"""The import-time CPU check of the x86-64-v3 build."""

from legkit._build import X86_64_V3_FLAGS, missing_cpu_features


def cpuinfo(flags: list[str]) -> str:
    return "processor\t: 0\nvendor_id\t: GenuineIntel\nflags\t\t: " + " ".join(flags) + "\nbugs\t\t: spectre_v1\n"


def test_a_cpu_with_every_feature_misses_none() -> None:
    assert missing_cpu_features(cpuinfo(["fpu", "sse2", *X86_64_V3_FLAGS])) == []


def test_missing_features_are_named_in_order() -> None:
    flags = [f for f in X86_64_V3_FLAGS if f not in ("avx2", "fma")]
    assert missing_cpu_features(cpuinfo(flags)) == ["avx2", "fma"]


def test_a_pre_haswell_cpu_misses_the_v3_features() -> None:
    # Sandy Bridge: AVX but no AVX2, BMI, FMA, F16C or MOVBE.
    sandy_bridge = ["fpu", "sse2", "cx16", "lahf_lm", "popcnt", "sse4_1", "sse4_2", "ssse3", "avx", "xsave"]
    assert missing_cpu_features(cpuinfo(sandy_bridge)) == ["avx2", "bmi1", "bmi2", "f16c", "fma", "abm", "movbe"]


def test_this_machine_passes() -> None:
    with open("/proc/cpuinfo", encoding="utf-8") as f:
        text = f.read()
    assert missing_cpu_features(text) == [], "the test machine itself must run the x86-64-v3 build"
