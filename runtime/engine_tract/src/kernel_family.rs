//! The one rule that names the family of f32 kernels tract 0.23.9 runs on this CPU. Digests
//! committed from a run (the C example's, the harness's) are kept per family, so every consumer
//! asks this module: Rust directly, C through `satmap_kernel_family()` (the C example picks its
//! digest file with it), Python and scripts through `satmap-sim kernel-family`. No other copy of
//! the rule exists.
//!
//! Outputs are bit-identical run to run and across thread counts within a family, not across
//! families: the kernels' tiling changes the summation order (measured: the demo drive's run
//! digest differs between an AVX-512 Xeon, an AVX-512 EPYC and an AVX2 EPYC, values within 2e-5;
//! the C scenario's digests differ again on a NEON core, `examples/c/expected-aarch64-neon.txt`).

use core::ffi::CStr;

/// A family of tract kernels: the same family computes the same bits.
///
/// On x86-64 the vendor is part of the family (tract keeps one matmul cost model per vendor, so
/// the same instruction set gets other tiles on another vendor; `TRACT_X86_KIND=intel|amd|other`
/// overrides the vendor, as it does in tract) and the tier is AVX-512F, AVX2 with FMA, or
/// neither. On aarch64 tract picks its SVE kernels where the core has SVE and its NEON kernels
/// otherwise (the Cortex-A53/A55 variants of the NEON kernels keep the generic ones' order:
/// cortex-a53, a72, a76 and neoverse-n1 under emulation gave the same digests).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum KernelFamily {
    /// Intel with AVX-512F.
    IntelAvx512f,
    /// Intel with AVX2 and FMA.
    IntelFma,
    /// Intel without either.
    IntelGeneric,
    /// AMD with AVX-512F.
    AmdAvx512f,
    /// AMD with AVX2 and FMA.
    AmdFma,
    /// AMD without either.
    AmdGeneric,
    /// Another x86-64 vendor with AVX-512F.
    OtherAvx512f,
    /// Another x86-64 vendor with AVX2 and FMA.
    OtherFma,
    /// Another x86-64 vendor without either.
    OtherGeneric,
    /// aarch64 without SVE: tract's NEON kernels (every listed ECU application core).
    Aarch64Neon,
    /// aarch64 with SVE: tract's SVE kernels.
    Aarch64Sve,
    /// Any other architecture: tract's portable kernels.
    Generic,
}

impl KernelFamily {
    /// The family of this process's CPU.
    #[must_use]
    pub fn detect() -> Self {
        detect()
    }

    /// The family's name: the suffix of the per-family digest files (`expected-<name>.txt`).
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self.c_name().to_str() {
            Ok(s) => s,
            Err(_) => "generic",
        }
    }

    /// [`Self::name`] as a NUL-terminated string, for the C API.
    #[must_use]
    pub const fn c_name(self) -> &'static CStr {
        match self {
            Self::IntelAvx512f => c"intel-avx512f",
            Self::IntelFma => c"intel-fma",
            Self::IntelGeneric => c"intel-generic",
            Self::AmdAvx512f => c"amd-avx512f",
            Self::AmdFma => c"amd-fma",
            Self::AmdGeneric => c"amd-generic",
            Self::OtherAvx512f => c"other-avx512f",
            Self::OtherFma => c"other-fma",
            Self::OtherGeneric => c"other-generic",
            Self::Aarch64Neon => c"aarch64-neon",
            Self::Aarch64Sve => c"aarch64-sve",
            Self::Generic => c"generic",
        }
    }
}

/// [`KernelFamily::detect`]'s name: `intel-avx512f`, `amd-fma`, `aarch64-neon`, ...
#[must_use]
pub fn kernel_family() -> &'static str {
    KernelFamily::detect().name()
}

#[cfg(target_arch = "x86_64")]
fn detect() -> KernelFamily {
    #[derive(Clone, Copy)]
    enum Vendor {
        Intel,
        Amd,
        Other,
    }
    #[derive(Clone, Copy)]
    enum Tier {
        Avx512f,
        Fma,
        Generic,
    }
    let vendor = match std::env::var("TRACT_X86_KIND").ok().as_deref() {
        Some("intel") => Vendor::Intel,
        Some("amd") => Vendor::Amd,
        Some(_) => Vendor::Other,
        None => match &cpuid_vendor() {
            b"GenuineIntel" => Vendor::Intel,
            b"AuthenticAMD" => Vendor::Amd,
            _ => Vendor::Other,
        },
    };
    let tier = if std::is_x86_feature_detected!("avx512f") {
        Tier::Avx512f
    } else if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
        Tier::Fma
    } else {
        Tier::Generic
    };
    match (vendor, tier) {
        (Vendor::Intel, Tier::Avx512f) => KernelFamily::IntelAvx512f,
        (Vendor::Intel, Tier::Fma) => KernelFamily::IntelFma,
        (Vendor::Intel, Tier::Generic) => KernelFamily::IntelGeneric,
        (Vendor::Amd, Tier::Avx512f) => KernelFamily::AmdAvx512f,
        (Vendor::Amd, Tier::Fma) => KernelFamily::AmdFma,
        (Vendor::Amd, Tier::Generic) => KernelFamily::AmdGeneric,
        (Vendor::Other, Tier::Avx512f) => KernelFamily::OtherAvx512f,
        (Vendor::Other, Tier::Fma) => KernelFamily::OtherFma,
        (Vendor::Other, Tier::Generic) => KernelFamily::OtherGeneric,
    }
}

/// The CPU vendor string of CPUID leaf 0.
#[cfg(target_arch = "x86_64")]
fn cpuid_vendor() -> [u8; 12] {
    // CPUID leaf 0 exists on every x86-64 CPU (`unsafe` only on older toolchains, hence the
    // allow).
    #[allow(unused_unsafe)]
    // SAFETY: CPUID is always available on x86-64 and has no side effects.
    let id = unsafe { std::arch::x86_64::__cpuid(0) };
    let mut s = [0u8; 12];
    s[0..4].copy_from_slice(&id.ebx.to_le_bytes());
    s[4..8].copy_from_slice(&id.edx.to_le_bytes());
    s[8..12].copy_from_slice(&id.ecx.to_le_bytes());
    s
}

#[cfg(target_arch = "aarch64")]
fn detect() -> KernelFamily {
    if std::arch::is_aarch64_feature_detected!("sve") {
        KernelFamily::Aarch64Sve
    } else {
        KernelFamily::Aarch64Neon
    }
}

#[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
fn detect() -> KernelFamily {
    KernelFamily::Generic
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_c_names_agree() {
        let all = [
            KernelFamily::IntelAvx512f,
            KernelFamily::IntelFma,
            KernelFamily::IntelGeneric,
            KernelFamily::AmdAvx512f,
            KernelFamily::AmdFma,
            KernelFamily::AmdGeneric,
            KernelFamily::OtherAvx512f,
            KernelFamily::OtherFma,
            KernelFamily::OtherGeneric,
            KernelFamily::Aarch64Neon,
            KernelFamily::Aarch64Sve,
            KernelFamily::Generic,
        ];
        let names: std::collections::BTreeSet<_> = all.iter().map(|f| f.name()).collect();
        assert_eq!(names.len(), all.len(), "every family has its own name");
        for f in all {
            assert_eq!(f.c_name().to_str().unwrap(), f.name());
        }
    }

    #[test]
    fn this_cpu_has_the_family_of_its_architecture() {
        let name = kernel_family();
        #[cfg(target_arch = "x86_64")]
        assert!(
            ["intel-", "amd-", "other-"]
                .iter()
                .any(|v| name.starts_with(v)),
            "{name}"
        );
        #[cfg(target_arch = "aarch64")]
        assert!(name.starts_with("aarch64-"), "{name}");
        println!("kernel family here: {name}");
    }
}
