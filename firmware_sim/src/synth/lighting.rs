//! Lighting conditions of a drive: colour gain, contrast, fog and sky, applied per pixel by the
//! camera renderer.

use serde::{Deserialize, Serialize};

/// Named lighting conditions.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum LightingPreset {
    /// Clear day.
    Day,
    /// Low warm light, dark sky.
    Dusk,
    /// Rain-like: grey, low contrast, strong haze.
    Rain,
}

impl LightingPreset {
    /// All presets.
    pub const ALL: [Self; 3] = [Self::Day, Self::Dusk, Self::Rain];

    /// The parameters of the preset.
    #[must_use]
    pub fn lighting(self) -> Lighting {
        match self {
            Self::Day => Lighting {
                gain: [1.05, 1.05, 1.02],
                contrast: 1.0,
                fog_density_per_m: 0.004,
                fog: [190.0, 200.0, 215.0],
                sky_horizon: [200.0, 215.0, 232.0],
                sky_zenith: [95.0, 145.0, 215.0],
                noise_amplitude: 4.0,
            },
            Self::Dusk => Lighting {
                gain: [0.78, 0.52, 0.42],
                contrast: 0.9,
                fog_density_per_m: 0.008,
                fog: [120.0, 80.0, 70.0],
                sky_horizon: [215.0, 120.0, 70.0],
                sky_zenith: [35.0, 40.0, 80.0],
                noise_amplitude: 7.0,
            },
            Self::Rain => Lighting {
                gain: [0.72, 0.75, 0.8],
                contrast: 0.55,
                fog_density_per_m: 0.03,
                fog: [140.0, 145.0, 150.0],
                sky_horizon: [150.0, 154.0, 160.0],
                sky_zenith: [110.0, 114.0, 122.0],
                noise_amplitude: 9.0,
            },
        }
    }
}

/// Per-pixel lighting parameters (colours on a 0..255 scale).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lighting {
    /// Multiplicative colour gain on surfaces.
    pub gain: [f32; 3],
    /// Contrast about mid-grey (1 = unchanged).
    pub contrast: f32,
    /// Exponential haze density, per metre of range.
    pub fog_density_per_m: f32,
    /// Haze colour.
    pub fog: [f32; 3],
    /// Sky colour at the horizon.
    pub sky_horizon: [f32; 3],
    /// Sky colour straight up.
    pub sky_zenith: [f32; 3],
    /// Amplitude of per-pixel sensor noise.
    pub noise_amplitude: f32,
}

impl Lighting {
    /// Lit surface colour at `range_m` from the camera.
    #[inline]
    #[must_use]
    pub fn surface(&self, albedo: [f32; 3], range_m: f32) -> [f32; 3] {
        let haze = 1.0 - (-self.fog_density_per_m * range_m).exp();
        let mut out = [0.0; 3];
        for k in 0..3 {
            let lit = 128.0 + (albedo[k] * self.gain[k] - 128.0) * self.contrast;
            out[k] = lit + (self.fog[k] - lit) * haze;
        }
        out
    }

    /// Sky colour for a ray whose upward component is `up` (0 at the horizon, 1 straight up).
    #[inline]
    #[must_use]
    pub fn sky(&self, up: f32) -> [f32; 3] {
        let t = up.clamp(0.0, 1.0).sqrt();
        core::array::from_fn(|k| {
            let c = self.sky_horizon[k] + (self.sky_zenith[k] - self.sky_horizon[k]) * t;
            128.0 + (c - 128.0) * self.contrast.max(0.8)
        })
    }
}
