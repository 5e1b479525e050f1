//! The instruction-set tiers of the kernels and the one rule that chooses the tier a process
//! runs: AVX-512F where the CPU has it, none elsewhere (tract's own kernels stay, see
//! [`Tier::default_here`]), or what `SATMAP_KERNEL_TIER` forces.

use std::sync::OnceLock;

/// The environment variable that forces a tier: `auto` (or unset, or empty) for the default,
/// `tract` for none (tract's own products everywhere), or a [`Tier::name`].
pub const TIER_ENV: &str = "SATMAP_KERNEL_TIER";

/// One implementation of the kernels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Tier {
    /// Portable scalar Rust: the definition of the bits, on every CPU (slow: `f32::mul_add`
    /// is a library call on a CPU compiled for without FMA).
    Generic,
    /// x86-64 with AVX2 and FMA: 8-lane vectors, the tier of AVX2-only servers and x86 ECUs.
    X86_64Avx2Fma,
    /// x86-64 with AVX-512F: 16-lane vectors with masked edges.
    X86_64Avx512f,
    /// aarch64 with NEON (every aarch64 core): 4-lane vectors.
    Aarch64Neon,
}

impl Tier {
    /// Every tier, the reference first.
    pub const ALL: [Self; 4] = [
        Self::Generic,
        Self::X86_64Avx2Fma,
        Self::X86_64Avx512f,
        Self::Aarch64Neon,
    ];

    /// The tier's name in [`TIER_ENV`] and in reports.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Generic => "generic",
            Self::X86_64Avx2Fma => "avx2-fma",
            Self::X86_64Avx512f => "avx512f",
            Self::Aarch64Neon => "neon",
        }
    }

    /// The tier named `name` ([`Self::name`]).
    #[must_use]
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|t| t.name() == name)
    }

    /// Whether this CPU has the tier's instructions.
    #[must_use]
    pub fn runs_here(self) -> bool {
        match self {
            Self::Generic => true,
            #[cfg(target_arch = "x86_64")]
            Self::X86_64Avx2Fma => {
                std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")
            }
            #[cfg(target_arch = "x86_64")]
            Self::X86_64Avx512f => std::is_x86_feature_detected!("avx512f"),
            #[cfg(target_arch = "aarch64")]
            Self::Aarch64Neon => std::arch::is_aarch64_feature_detected!("neon"),
            _ => false,
        }
    }

    /// The tier the engine's products run on when nothing is forced: AVX-512F where the CPU
    /// has it, none elsewhere. The AVX2 + FMA and NEON tiers give the same bits but run only
    /// when forced. On a Cortex-A76 (instructions retired under qemu, docs/perf.md "Kernel
    /// tiers") tract's own NEON kernels run every stage in 0.27-0.59 of the instructions the
    /// NEON tier's passes do, so tract keeps the products there. On an AVX2-only CPU neither
    /// our tier's speed against tract's AVX2 kernels nor those families' digests with it (the
    /// native passes sum the image stem in another order than tract's direct convolution)
    /// have been measured yet.
    #[must_use]
    pub fn default_here() -> Option<Self> {
        Some(Self::X86_64Avx512f).filter(|t| t.runs_here())
    }

    /// The tier a value of [`TIER_ENV`] asks for (`None`: tract's products).
    ///
    /// # Errors
    /// A name that is no tier, or a tier this CPU lacks.
    pub fn choose(value: Option<&str>) -> Result<Option<Self>, TierError> {
        match value.map(str::trim) {
            None | Some("" | "auto") => Ok(Self::default_here()),
            Some("tract") => Ok(None),
            Some(name) => {
                let tier = Self::from_name(name).ok_or_else(|| TierError::Unknown {
                    value: name.to_owned(),
                })?;
                if tier.runs_here() {
                    Ok(Some(tier))
                } else {
                    Err(TierError::NotOnThisCpu { tier })
                }
            }
        }
    }

    /// The tier of this process: [`Self::choose`] over [`TIER_ENV`], read once.
    ///
    /// # Errors
    /// As [`Self::choose`] (every call returns the same answer).
    pub fn chosen() -> Result<Option<Self>, TierError> {
        static CHOSEN: OnceLock<Result<Option<Tier>, TierError>> = OnceLock::new();
        CHOSEN
            .get_or_init(|| {
                let value = std::env::var(TIER_ENV).ok();
                Self::choose(value.as_deref())
            })
            .clone()
    }
}

impl core::fmt::Display for Tier {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// A [`TIER_ENV`] value that cannot be run.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum TierError {
    /// The value names no tier.
    #[error(
        "{TIER_ENV}={value:?} names no kernel tier (auto, tract, generic, avx2-fma, avx512f, neon)"
    )]
    Unknown {
        /// The value given.
        value: String,
    },
    /// The tier's instructions are not on this CPU.
    #[error("{TIER_ENV}={tier}: this CPU lacks the tier's instructions")]
    NotOnThisCpu {
        /// The tier asked for.
        tier: Tier,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_values_choose_as_documented() {
        for t in Tier::ALL {
            assert_eq!(Tier::from_name(t.name()), Some(t));
        }
        assert_eq!(Tier::choose(None), Ok(Tier::default_here()));
        assert_eq!(Tier::choose(Some(" auto ")), Ok(Tier::default_here()));
        assert_eq!(Tier::choose(Some("")), Ok(Tier::default_here()));
        assert_eq!(Tier::choose(Some("tract")), Ok(None));
        assert_eq!(Tier::choose(Some("generic")), Ok(Some(Tier::Generic)));
        assert_eq!(
            Tier::choose(Some("avx3")),
            Err(TierError::Unknown {
                value: "avx3".into()
            })
        );
        for t in Tier::ALL {
            let got = Tier::choose(Some(t.name()));
            if t.runs_here() {
                assert_eq!(got, Ok(Some(t)));
            } else {
                assert_eq!(got, Err(TierError::NotOnThisCpu { tier: t }));
                assert!(got.unwrap_err().to_string().contains(t.name()));
            }
        }
        // Some tier is absent on every CPU (x86 has no NEON, aarch64 no AVX).
        assert!(Tier::ALL.iter().any(|t| !t.runs_here()));
    }
}
