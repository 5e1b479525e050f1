//! A stage's graph as the engine reads it: the checked parse of a bundle's bytes into tract's
//! typed model ([`load`]), and the matching and patching helpers every pass uses
//! ([`matching`]). A leaf of the engine: it imports no op and no pass.

pub mod load;
pub mod matching;
