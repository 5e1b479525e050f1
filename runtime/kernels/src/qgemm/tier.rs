//! The integer product's instruction-set tiers and the rule that chooses one: the widest
//! dot-product instructions the CPU has (AVX-512 VNNI, then AVX-VNNI, then AVX2's `vpmaddwd`
//! on x86-64; `sdot` on aarch64), the portable tier elsewhere, or what [`INT_TIER_ENV`] forces.
//! Every tier gives the same bits ([`super`]), so the choice is one of speed only.

use std::sync::OnceLock;

/// The environment variable that forces an integer tier: `auto` (or unset, or empty) for the
/// default, or an [`IntTier::name`].
pub const INT_TIER_ENV: &str = "SATMAP_INT_TIER";

/// One implementation of the integer product.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum IntTier {
    /// Portable scalar Rust: the definition of the sums, on every CPU.
    Generic,
    /// x86-64 with AVX2: bytes widened to i16, pairs summed by `vpmaddwd`.
    X86_64Avx2,
    /// x86-64 with AVX-VNNI: `vpdpbusd` on 8-lane vectors (Alder Lake and later cores).
    X86_64AvxVnni,
    /// x86-64 with AVX-512 VNNI: `vpdpbusd` on 16-lane vectors (Cascade Lake and later).
    X86_64Avx512Vnni,
    /// aarch64 with the dot-product instructions (Armv8.2 `dotprod`: Cortex-A76, A78AE).
    Aarch64Dotprod,
}

impl IntTier {
    /// Every tier, the reference first.
    pub const ALL: [Self; 5] = [
        Self::Generic,
        Self::X86_64Avx2,
        Self::X86_64AvxVnni,
        Self::X86_64Avx512Vnni,
        Self::Aarch64Dotprod,
    ];

    /// The tier's name in [`INT_TIER_ENV`] and in reports.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Generic => "generic",
            Self::X86_64Avx2 => "avx2",
            Self::X86_64AvxVnni => "avx-vnni",
            Self::X86_64Avx512Vnni => "avx512-vnni",
            Self::Aarch64Dotprod => "dotprod",
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
            // Every feature the tier's functions enable (`target_feature`), so their safety
            // contracts hold.
            Self::X86_64Avx2 => {
                std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")
            }
            #[cfg(target_arch = "x86_64")]
            Self::X86_64AvxVnni => {
                std::is_x86_feature_detected!("avx2")
                    && std::is_x86_feature_detected!("fma")
                    && std::is_x86_feature_detected!("avxvnni")
            }
            #[cfg(target_arch = "x86_64")]
            Self::X86_64Avx512Vnni => {
                std::is_x86_feature_detected!("avx512f")
                    && std::is_x86_feature_detected!("avx512bw")
                    && std::is_x86_feature_detected!("avx512vnni")
            }
            #[cfg(target_arch = "aarch64")]
            Self::Aarch64Dotprod => std::arch::is_aarch64_feature_detected!("dotprod"),
            _ => false,
        }
    }

    /// The widest tier this CPU has.
    #[must_use]
    pub fn default_here() -> Self {
        [
            Self::X86_64Avx512Vnni,
            Self::X86_64AvxVnni,
            Self::Aarch64Dotprod,
            Self::X86_64Avx2,
        ]
        .into_iter()
        .find(|t| t.runs_here())
        .unwrap_or(Self::Generic)
    }

    /// The tier a value of [`INT_TIER_ENV`] asks for.
    ///
    /// # Errors
    /// A name that is no tier, or a tier this CPU lacks.
    pub fn choose(value: Option<&str>) -> Result<Self, IntTierError> {
        match value.map(str::trim) {
            None | Some("" | "auto") => Ok(Self::default_here()),
            Some(name) => {
                let tier = Self::from_name(name).ok_or_else(|| IntTierError::Unknown {
                    value: name.to_owned(),
                })?;
                if tier.runs_here() {
                    Ok(tier)
                } else {
                    Err(IntTierError::NotOnThisCpu { tier })
                }
            }
        }
    }

    /// The tier of this process: [`Self::choose`] over [`INT_TIER_ENV`], read once.
    ///
    /// # Errors
    /// As [`Self::choose`] (every call returns the same answer).
    pub fn chosen() -> Result<Self, IntTierError> {
        static CHOSEN: OnceLock<Result<IntTier, IntTierError>> = OnceLock::new();
        CHOSEN
            .get_or_init(|| Self::choose(std::env::var(INT_TIER_ENV).ok().as_deref()))
            .clone()
    }
}

impl core::fmt::Display for IntTier {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// An [`INT_TIER_ENV`] value that cannot be run.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum IntTierError {
    /// The value names no tier.
    #[error(
        "{INT_TIER_ENV}={value:?} names no integer tier (auto, generic, avx2, avx-vnni, avx512-vnni, dotprod)"
    )]
    Unknown {
        /// The value given.
        value: String,
    },
    /// The tier's instructions are not on this CPU.
    #[error("{INT_TIER_ENV}={tier}: this CPU lacks the tier's instructions")]
    NotOnThisCpu {
        /// The tier asked for.
        tier: IntTier,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_values_choose_as_documented() {
        for t in IntTier::ALL {
            assert_eq!(IntTier::from_name(t.name()), Some(t));
            let got = IntTier::choose(Some(t.name()));
            if t.runs_here() {
                assert_eq!(got, Ok(t));
            } else {
                assert_eq!(got, Err(IntTierError::NotOnThisCpu { tier: t }));
            }
        }
        assert_eq!(IntTier::choose(None), Ok(IntTier::default_here()));
        assert!(IntTier::default_here().runs_here());
        assert!(matches!(
            IntTier::choose(Some("sse")),
            Err(IntTierError::Unknown { .. })
        ));
    }
}
