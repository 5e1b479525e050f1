//! Which instruction-set tiers' tests run here. A tier's tests need its instructions on the
//! machine that builds and runs them (the host): a host build on a CPU with AVX-512F sets
//! `satmap_tier_avx512f`, with AVX2 and FMA `satmap_tier_avx2_fma`; elsewhere (another CPU, a
//! cross build) those tests are reported as ignored with the reason, never a silent `ok`. NEON is
//! part of every aarch64 target, so its tests follow `target_arch` (run under qemu by
//! `make test-aarch64`). `tests/tiers.rs` fails if a cfg and the CPU disagree (a target folder
//! built on another machine).

fn main() {
    println!("cargo::rustc-check-cfg=cfg(satmap_tier_avx512f)");
    println!("cargo::rustc-check-cfg=cfg(satmap_tier_avx2_fma)");
    println!("cargo::rustc-check-cfg=cfg(satmap_itier_avx2)");
    println!("cargo::rustc-check-cfg=cfg(satmap_itier_avx_vnni)");
    println!("cargo::rustc-check-cfg=cfg(satmap_itier_avx512_vnni)");
    let host = std::env::var("HOST").unwrap_or_default();
    let target = std::env::var("TARGET").unwrap_or_default();
    #[cfg(target_arch = "x86_64")]
    if host == target {
        if std::is_x86_feature_detected!("avx512f") {
            println!("cargo::rustc-cfg=satmap_tier_avx512f");
        }
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
            println!("cargo::rustc-cfg=satmap_tier_avx2_fma");
        }
        // The integer product's tiers (src/qgemm).
        if std::is_x86_feature_detected!("avx2") {
            println!("cargo::rustc-cfg=satmap_itier_avx2");
        }
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("avxvnni") {
            println!("cargo::rustc-cfg=satmap_itier_avx_vnni");
        }
        if std::is_x86_feature_detected!("avx512f") && std::is_x86_feature_detected!("avx512vnni") {
            println!("cargo::rustc-cfg=satmap_itier_avx512_vnni");
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (host, target);
}
