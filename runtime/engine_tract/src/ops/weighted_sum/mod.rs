//! The native kernel for the deformable samplers' corner sums: `ReduceSum(a * b, axis)` over one
//! middle axis, fused into one pass with a fixed summation order.
//!
//! Both deformable samplers (`bev_query`'s self-attention and `map_decoder`'s cross-attention,
//! `satmap_ref.sampling.bilinear_gather_sum`) end in `(corners * weights).sum(dim=2)` over
//! `[N, heads, 4 x points, dh]`. tract 0.23.9 reduces a middle axis through ndarray's generic
//! `sum_axis` (its fast paths cover the last and the leading axes), which was 58% of `bev_query`
//! and 23% of `map_decoder` in `nano` (docs/perf.md). At load, [`fuse_weighted_sums`]
//! (`pattern.rs`) rewrites every `Mul -> Reduce<Sum>` pair of that shape into
//! [`WeightedAxisSum`] (here), which reads both
//! operands once and never materialises the product.
//!
//! Order (the contract `satmap_ref.sampling.weighted_axis_sum` reproduces bit for bit): for every
//! output element, `acc = 0.0f32`, then for k ascending `acc = acc + a[k] * b[k]` (an f32
//! multiply, then an f32 add; no FMA), broadcasting as numpy does.

use tract_nnef::internal::*;

use satmap_kernels::sampling::{Operand, weighted_axis_sum};

mod pattern;
pub use pattern::fuse_weighted_sums;

/// `out = sum over axis of a * b` (a and b broadcast together; the axis kept, as size 1).
///
/// With `gathered`, `a` is not an input: it is `data[indices]` (a Gather of rows of a `[R, dh]`
/// matrix) reshaped to `gathered`, whose last dim is `dh` and whose summed axis is the one
/// before it; the inputs are then `(data, indices, b)` and the rows are read in place. The
/// indices are i64, or f32 when the graph cast them from f32 (the cast is folded in: tract's
/// f32 -> i64 Cast ran at ~18 ns an element).
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct WeightedAxisSum {
    /// The summed axis, counted in the broadcast shape (never the last one).
    pub axis: usize,
    /// The shape of the gathered operand, when it is gathered.
    pub gathered: Option<TVec<usize>>,
}

impl Op for WeightedAxisSum {
    fn name(&self) -> StaticName {
        "WeightedAxisSum".into()
    }
    op_as_typed_op!();
}

impl EvalOp for WeightedAxisSum {
    op_out_of_plan!();

    fn eval(&self, _ctx: &EvalContext, inputs: TVec<TValue>) -> TractResult<TVec<TValue>> {
        let (full, b_in): (TVec<usize>, &TValue) = match &self.gathered {
            Some(shape) => {
                ensure!(
                    inputs.len() == 3,
                    "gathered WeightedAxisSum takes three inputs"
                );
                let full = tract_nnef::tract_core::broadcast::multi_broadcast(&[
                    &**shape,
                    inputs[2].shape(),
                ])?;
                ensure!(
                    full == *shape,
                    "the weights broadcast beyond the gathered operand"
                );
                (full, &inputs[2])
            }
            None => {
                ensure!(inputs.len() == 2, "WeightedAxisSum takes two inputs");
                let full = tract_nnef::tract_core::broadcast::multi_broadcast(&[
                    inputs[0].shape(),
                    inputs[1].shape(),
                ])?;
                (full, &inputs[1])
            }
        };
        ensure!(
            self.axis + 1 < full.len(),
            "WeightedAxisSum over the last axis"
        );
        let outer: usize = full[..self.axis].iter().product();
        let k_len = full[self.axis];
        let inner: usize = full[self.axis + 1..].iter().product();
        // Operands in the two layouts the fast loop reads are read in place; anything else (a
        // broadcast over the outer or summed dims) is materialised first: correct, slower, and
        // never what our graphs hand it.
        let fast = |t: &TValue| {
            let pad = full.len() - t.rank();
            let dim = |d: usize| if d < pad { 1 } else { t.shape()[d - pad] };
            let head_same = (0..=self.axis).all(|d| dim(d) == full[d]);
            let tail = self.axis + 1..full.len();
            let inner_ok =
                tail.clone().all(|d| dim(d) == full[d]) || tail.clone().all(|d| dim(d) == 1);
            head_same && inner_ok
        };
        let owned = |t: &TValue| -> TractResult<Option<Tensor>> {
            if fast(t) {
                Ok(None)
            } else {
                t.broadcast_to_shape(&full).map(Some)
            }
        };
        let b_owned = owned(b_in)?;
        let b = plain_operand(b_in, &b_owned, outer * k_len)?;
        let mut out = vec![0.0f32; outer * inner];
        match &self.gathered {
            Some(_) => {
                let data = inputs[0].try_as_plain_ram()?.as_slice::<f32>()?;
                // Indices cast from f32 in the graph are taken before the cast and converted
                // here as tract's Cast converts them (`as i64`: toward zero, saturating).
                let converted: Vec<i64>;
                let rows: &[i64] = if inputs[1].datum_type() == f32::datum_type() {
                    let f = inputs[1].try_as_plain_ram()?;
                    converted = f.as_slice::<f32>()?.iter().map(|&x| x as i64).collect();
                    &converted
                } else {
                    inputs[1].try_as_plain_ram()?.as_slice::<i64>()?
                };
                ensure!(inputs[0].rank() == 2 && inputs[0].shape()[1] == inner);
                ensure!(
                    rows.len() == outer * k_len,
                    "gather indices do not fill the operand"
                );
                let n_rows = inputs[0].shape()[0] as i64;
                ensure!(
                    rows.iter().all(|&r| (0..n_rows).contains(&r)),
                    "gather index out of range (0..{n_rows})"
                );
                let a = Operand {
                    data,
                    inner_len: inner,
                    rows: Some(rows),
                };
                ensure!(
                    weighted_axis_sum(&a, &b, k_len, inner, &mut out),
                    "WeightedAxisSum operands shorter than their shapes"
                );
            }
            None => {
                let a_owned = owned(&inputs[0])?;
                let a = plain_operand(&inputs[0], &a_owned, outer * k_len)?;
                ensure!(
                    weighted_axis_sum(&a, &b, k_len, inner, &mut out),
                    "WeightedAxisSum operands shorter than their shapes"
                );
            }
        }
        let mut out_shape: TVec<usize> = full.clone();
        out_shape[self.axis] = 1;
        Ok(tvec!(Tensor::from_shape(&out_shape, &out)?.into_tvalue()))
    }
}

/// `t` (or its materialised broadcast `o`) as an [`Operand`] of `rows` rows.
fn plain_operand<'a>(
    t: &'a TValue,
    o: &'a Option<Tensor>,
    rows: usize,
) -> TractResult<Operand<'a>> {
    let t: &Tensor = o.as_ref().unwrap_or(t);
    let data = t.try_as_plain_ram()?.as_slice::<f32>()?;
    Ok(Operand {
        data,
        inner_len: data.len() / rows.max(1),
        rows: None,
    })
}

impl TypedOp for WeightedAxisSum {
    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        let mut shape = match &self.gathered {
            Some(g) => {
                ensure!(inputs.len() == 3);
                ensure!(inputs[0].datum_type == f32::datum_type());
                ensure!(matches!(
                    inputs[1].datum_type,
                    DatumType::I64 | DatumType::F32
                ));
                ensure!(inputs[2].datum_type == f32::datum_type());
                g.iter().map(|&d| d.to_dim()).collect::<TVec<TDim>>()
            }
            None => {
                ensure!(inputs.len() == 2);
                ensure!(inputs.iter().all(|f| f.datum_type == f32::datum_type()));
                tract_nnef::tract_core::broadcast::multi_broadcast(&[
                    &*inputs[0].shape.to_tvec(),
                    &*inputs[1].shape.to_tvec(),
                ])?
            }
        };
        ensure!(self.axis + 1 < shape.len());
        shape[self.axis] = 1.to_dim();
        Ok(tvec!(f32::fact(shape)))
    }

    fn cost(&self, inputs: &[&TypedFact]) -> TractResult<TVec<(Cost, TDim)>> {
        let n: TDim = inputs[0].shape.iter().product();
        Ok(tvec!((Cost::FMA(f32::datum_type()), n)))
    }

    as_op!();
}

#[cfg(test)]
mod tests {
    //! The kernel against `satmap_ref.sampling.kernel_golden` (committed in
    //! `models/golden/kernels/`), bit for bit, through the same rewrite the engine applies.

    use super::*;
    use crate::TractEngine;
    use crate::test_support::{
        bits, committed_rewrites, golden_tensor as tensor, kernel_golden as golden,
    };
    use satmap_core::engine::Stage;
    use tract_nnef::tract_core::ops::math::mul;
    use tract_nnef::tract_core::ops::nn::{Reduce, Reducer};

    /// `Mul -> Reduce<Sum>(2)` over `a` (optionally a row gather) and `b`, rewritten.
    fn fused_model(gathered: bool) -> (TypedModel, usize) {
        fused_model_with(gathered, false)
    }

    /// As [`fused_model`]; `f32_indices`: the indices arrive as f32 and are cast in the graph.
    fn fused_model_with(gathered: bool, f32_indices: bool) -> (TypedModel, usize) {
        let mut m = TypedModel::default();
        let b = m.add_source("b", f32::fact([6, 3, 8, 1])).unwrap();
        let a = if gathered {
            let data = m.add_source("data", f32::fact([20, 5])).unwrap();
            let idx = if f32_indices {
                let f = m.add_source("indices", f32::fact([144])).unwrap();
                let cast = tract_nnef::tract_core::ops::cast::cast(i64::datum_type());
                m.wire_node("cast", cast, &[f]).unwrap()[0]
            } else {
                m.add_source("indices", i64::fact([144])).unwrap()
            };
            let g = m
                .wire_node(
                    "gather",
                    tract_nnef::tract_core::ops::array::Gather::new(0),
                    &[data, idx],
                )
                .unwrap();
            let to: TVec<TDim> = tvec![6.into(), 3.into(), 8.into()];
            m.wire_node("reshape", AxisOp::Reshape(0, tvec![144.into()], to), &g)
                .unwrap()[0]
        } else {
            m.add_source("a", f32::fact([6, 3, 8, 5])).unwrap()
        };
        let p = m.wire_node("mul", mul(), &[a, b]).unwrap();
        let s = m
            .wire_node("sum", Reduce::new(tvec![2], Reducer::Sum), &p)
            .unwrap();
        m.select_output_outlets(&s).unwrap();
        let m = m.into_decluttered().unwrap();
        let (m, fused) = fuse_weighted_sums(m).unwrap();
        let found = m
            .nodes()
            .iter()
            .filter_map(|n| n.op_as::<WeightedAxisSum>());
        let ops: Vec<_> = found.collect();
        assert_eq!(ops.len(), 1);
        assert_eq!(ops[0].gathered.is_some(), gathered);
        let casts = m
            .nodes()
            .iter()
            .filter(|n| n.op_is::<tract_nnef::tract_core::ops::cast::Cast>())
            .count();
        assert_eq!(casts, 0, "the index cast is folded into the kernel");
        (m.into_optimized().unwrap(), fused)
    }

    #[test]
    fn the_fused_sum_is_the_python_reference_bit_for_bit() {
        let bytes = golden();
        let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
        let (model, fused) = fused_model(false);
        let plan = model.into_runnable().unwrap();
        assert_eq!(fused, 1);
        let out = plan
            .run(tvec![
                tensor(&st, "b").into_tvalue(),
                tensor(&st, "a").into_tvalue()
            ])
            .unwrap();
        assert_eq!(out[0].shape(), [6, 3, 1, 5]);
        assert_eq!(bits(&out[0]), bits(&tensor(&st, "out")));
    }

    #[test]
    fn the_gathered_sum_reads_rows_in_place_and_refuses_a_bad_index() {
        let bytes = golden();
        let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
        let (model, fused) = fused_model(true);
        let plan = model.into_runnable().unwrap();
        assert_eq!(fused, 1);
        let run = |idx: Tensor| {
            plan.run(tvec![
                tensor(&st, "b").into_tvalue(),
                tensor(&st, "data").into_tvalue(),
                idx.into_tvalue(),
            ])
        };
        let out = run(tensor(&st, "indices")).unwrap();
        assert_eq!(bits(&out[0]), bits(&tensor(&st, "gathered_out")));
        // An index past the data is an error value, and the plan still runs the next input.
        for bad in [20i64, -1] {
            let mut idx = tensor(&st, "indices");
            idx.try_as_plain_ram_mut()
                .unwrap()
                .as_slice_mut::<i64>()
                .unwrap()[7] = bad;
            let err = run(idx).unwrap_err();
            assert!(format!("{err:#}").contains("out of range"), "{err:#}");
        }
        let again = run(tensor(&st, "indices")).unwrap();
        assert_eq!(bits(&again[0]), bits(&tensor(&st, "gathered_out")));
    }

    #[test]
    fn indices_cast_from_f32_are_folded_in() {
        let bytes = golden();
        let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
        let (model, fused) = fused_model_with(true, true);
        assert_eq!(fused, 1);
        let plan = model.into_runnable().unwrap();
        let idx = tensor(&st, "indices");
        let f: Vec<f32> = idx
            .try_as_plain_ram()
            .unwrap()
            .as_slice::<i64>()
            .unwrap()
            .iter()
            .map(|&i| i as f32)
            .collect();
        let run = |f: &[f32]| {
            plan.run(tvec![
                tensor(&st, "b").into_tvalue(),
                tensor(&st, "data").into_tvalue(),
                Tensor::from_shape(&[144], f).unwrap().into_tvalue(),
            ])
        };
        let out = run(&f).unwrap();
        assert_eq!(bits(&out[0]), bits(&tensor(&st, "gathered_out")));
        let mut bad = f.clone();
        bad[3] = f32::NAN; // `as i64` makes it 0: in range, as tract's Cast would
        assert!(run(&bad).is_ok());
        bad[3] = 1e9;
        assert!(run(&bad).is_err());
    }

    #[test]
    fn the_default_bundle_runs_its_native_kernels() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let engine = TractEngine::open(root.join("models/bundles/test.satmap")).unwrap();
        // The engine's load applies each rewrite as its own test does, in the same order.
        let got: Vec<_> = Stage::ALL.map(|s| engine.rewrites(s)).to_vec();
        let want: Vec<_> = Stage::ALL.map(committed_rewrites).to_vec();
        assert_eq!(got, want);
    }
}
