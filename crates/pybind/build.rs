//! Records the CPU features the extension is compiled for (`-C target-cpu=...` from `.cargo/config.toml` or
//! RUSTFLAGS), so that `legkit._build` checks the host against the build actually installed rather than a
//! fixed list: a `target-cpu=native` rebuild then imports on the CPU it was built on.

fn main() {
    // Cargo gives build scripts the target's enabled features as a comma-separated list ("avx,avx2,...").
    let features = std::env::var("CARGO_CFG_TARGET_FEATURE").unwrap_or_default();
    println!("cargo:rustc-env=LEGKIT_TARGET_FEATURES={features}");
    // Run again whenever the flags that choose the features change (the record must not go stale).
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=../../.cargo/config.toml");
    for flags in ["RUSTFLAGS", "CARGO_ENCODED_RUSTFLAGS", "CARGO_BUILD_RUSTFLAGS", "CARGO_TARGET_X86_64_UNKNOWN_LINUX_GNU_RUSTFLAGS"] {
        println!("cargo:rerun-if-env-changed={flags}");
    }
}
