//! What the precision tests of [`super`] share: a one-weight graph and a look at the tensor
//! files of the NNEF tar written from it.

use tract_nnef::internal::*;
use tract_nnef::tract_core::ops::math::add;

/// `y = x + w`, with `x` a source of `w`'s shape and `w` the constant named `w`.
pub fn model_adding(w: Tensor) -> TractResult<TypedModel> {
    let mut model = TypedModel::default();
    let x = model.add_source("x", f32::fact(w.shape()))?;
    let w = model.add_const("w", w)?;
    let y = model.wire_node("y", add(), &[x, w])?;
    model.select_output_outlets(&y)?;
    Ok(model)
}

/// Sizes of the tensor files (`.dat`) in an NNEF tar, smallest first.
pub fn dat_sizes(tar: &[u8]) -> TractResult<Vec<u64>> {
    let mut archive = tar::Archive::new(tar);
    let mut sizes: Vec<u64> = archive
        .entries()?
        .filter_map(Result::ok)
        .filter(|e| {
            e.path()
                .is_ok_and(|p| p.extension().is_some_and(|x| x == "dat"))
        })
        .map(|e| e.size())
        .collect();
    sizes.sort_unstable();
    Ok(sizes)
}
