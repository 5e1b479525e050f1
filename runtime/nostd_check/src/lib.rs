//! no_std canary (placeholder until the core lands).
#![no_std]
