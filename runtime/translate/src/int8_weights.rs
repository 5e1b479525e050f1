//! The int8 form of a stage graph: every weight matrix and kernel stored as int8 with one f32
//! scale per output channel (symmetric, zero point 0), widened to f32 inside the graph: int8
//! weights, f32 activations and arithmetic (W8A32).
//!
//! Why not integer arithmetic: on tract 0.23.9 every quantised form of our stages that computes
//! the right result was measured slower than f32 on this CPU, and none can be written as NNEF
//! (`docs/int8.md`, with the scripts). What int8 storage buys is a quarter of the f32 flash for
//! weights, with no calibration needed: activations are not quantised.
//!
//! The widening is `cast(int8 -> f32) * scale` in the stored graph. tract's NNEF writer runs
//! `prop_consts` before it writes, which would fold such a pair back into an f32 weight, so
//! [`write_tar`] lets tract translate the f32 graph to its NNEF document first, then rewrites
//! each weight's `variable` in that document into the int8 variable, its scales and the
//! widening, and writes the archive without folding again. At load on the target, tract's
//! optimiser folds each widening once, so the step runs the same f32 kernels on weights rounded
//! to int8. It folds only weights whose f32 form stays under 4 MiB (tract-core's
//! `CONST_FOLD_MEM_BUDGET`): larger ones (`nano`'s) stay int8 in RAM and are widened every step,
//! less memory for a slower step (docs/bundles.md, "Precision").
//!
//! What stays f32, and why: every tensor of fewer than [`MIN_INT8_ELEMENTS`] elements, of one
//! axis longer than 1 (biases and norms' gains, which tract's rewrites may have reshaped to
//! `[1, C]`: one scale for all their channels), or with fewer than [`MIN_CHANNEL_ELEMENTS`]
//! values per output channel (the reference points, `[N, 2]`: one scale per point would round a
//! coordinate by up to 1/254 of the point's larger one, 0.035 m of the `test` model's mean
//! Chamfer deviation, docs/int8.md); all activations. A few kB in all.

use std::collections::HashMap;

use tract_nnef::ast::{Assignment, Identifier, Literal, ProtoModel, RValue};
use tract_nnef::internal::*;
use tract_nnef::ser::{assignment, datum_type, ident, ints, invocation, named_arg, string};
use tract_nnef::tract_core::ops::cnn::{Conv, KernelFormat};
use tract_nnef::tract_core::ops::einsum::prefix_matmul::PrefixMatMul;
use tract_nnef::tract_core::ops::konst::Const;

/// Elements at which a constant with two axes longer than 1 may be stored as int8.
pub const MIN_INT8_ELEMENTS: usize = 64;

/// Values per output channel (the slice one scale covers) at which a constant is stored as int8.
pub const MIN_CHANNEL_ELEMENTS: usize = 16;

/// Largest magnitude of a stored weight: symmetric int8, -127..=127 (-128 unused, so a
/// channel's scale maps its largest weight exactly).
const Q_MAX: f32 = 127.0;

/// tar entries' modification time: 1 Jan 1980, what tract's deterministic writer uses.
const TAR_MTIME_S: u64 = 315_532_800;

/// What [`write_tar`] stored.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Int8Stored {
    /// Constants stored as int8.
    pub tensors: usize,
    /// Their elements (one byte each in the archive).
    pub elements: usize,
}

/// `model` (decluttered, f32) written as an NNEF tar with its weights stored as int8 (see the
/// module documentation), deterministically.
///
/// # Errors
/// tract's rewrite or serialisation error, or a weight that is not finite.
pub fn write_tar(
    nnef: &tract_nnef::framework::Nnef,
    model: &TypedModel,
) -> TractResult<(Vec<u8>, Int8Stored)> {
    // The writer's rewrites, done here once so the channel axes are read off the graph that is
    // written (the writer runs them again: they are already done).
    let mut model = model.clone();
    tract_nnef::ser::rewrite_model(&mut model)?;
    let axes = channel_axes(&model);
    let mut proto = tract_nnef::ser::to_proto_model(nnef, &model)?;
    ensure!(
        proto.quantization.is_none() && proto.resources.is_empty(),
        "the graph holds quantised tensors or resources of its own"
    );
    let stored = store_weights_as_int8(&mut proto, &axes)?;
    let mut tar = tar::Builder::new(Vec::new());
    let mut graph = Vec::new();
    tract_nnef::ast::dump::Dumper::new(nnef, &mut graph).document(&proto.doc)?;
    append(&mut tar, "graph.nnef", &graph)?;
    let mut labels: Vec<_> = proto.tensors.keys().collect();
    labels.sort();
    for label in labels {
        let mut data = Vec::new();
        tract_nnef::tensors::write_tensor(&mut data, &proto.tensors[label])?;
        // Labels are graph paths ("/encoder/conv.weight"): stored relative, as tract's writer
        // stores them and its reader looks them up.
        let path = format!("{}.dat", label.0);
        let path = if path.starts_with('/') {
            format!(".{path}")
        } else {
            path
        };
        append(&mut tar, &path, &data)?;
    }
    Ok((tar.into_inner()?, stored))
}

fn append(tar: &mut tar::Builder<Vec<u8>>, path: &str, data: &[u8]) -> TractResult<()> {
    let mut header = tar::Header::new_gnu();
    header.set_size(data.len() as u64);
    header.set_mode(0o644);
    header.set_mtime(TAR_MTIME_S);
    tar.append_data(&mut header, path, data)?;
    Ok(())
}

/// Whether a constant is a weight that may be stored as int8, before its channel axis is known.
fn is_int8_candidate(value: &Tensor) -> bool {
    value.datum_type() == f32::datum_type()
        && value.len() >= MIN_INT8_ELEMENTS
        && value.shape().iter().filter(|&&d| d > 1).count() >= 2
        && value.is_plain_ram()
}

/// Whether a candidate with output channels along `axis` is stored as int8: enough values share
/// each channel's scale (see the module documentation).
fn is_int8_weight(value: &Tensor, axis: usize) -> bool {
    is_int8_candidate(value)
        && value
            .shape()
            .get(axis)
            .is_some_and(|&c| c > 0 && value.len() / c >= MIN_CHANNEL_ELEMENTS)
}

/// Output-channel axis of each constant stored as int8, by node name (the label the NNEF writer
/// gives its tensor): the output-feature axis of a matmul operand, O of an OIHW kernel, else
/// axis 0. Any axis gives a correct widening; this one gives each output channel its own range.
/// A constant absent from the map stays f32.
fn channel_axes(model: &TypedModel) -> HashMap<String, usize> {
    let mut axes = HashMap::new();
    for node in &model.nodes {
        let Some(konst) = node.op_as::<Const>() else {
            continue;
        };
        let rank = konst.val().rank();
        if !is_int8_candidate(konst.val()) {
            continue;
        }
        let mut axis = 0;
        if let Some(consumer) = node.outputs[0].successors.first() {
            let user = model.node(consumer.node);
            if let Some(mm) = user.op_as::<PrefixMatMul>() {
                // a is [.., M, K] ([.., K, M] transposed), b is [.., K, N] ([.., N, K]).
                let along_last = if consumer.slot == 0 {
                    mm.transpose_a
                } else {
                    !mm.transpose_b
                };
                axis = if along_last { rank - 1 } else { rank - 2 };
            } else if let Some(conv) = user.op_as::<Conv>()
                && consumer.slot == 1
                && conv.kernel_fmt == KernelFormat::HWIO
            {
                // O last; OIHW and OHWI have it first. (The writer's rewrites leave OIHW.)
                axis = rank - 1;
            }
        }
        if is_int8_weight(konst.val(), axis) {
            axes.insert(node.name.clone(), axis);
        }
    }
    axes
}

/// The string value of `variable`'s `label` argument, if `right` is a `variable` invocation.
fn variable_label(right: &RValue) -> Option<&str> {
    let RValue::Invocation(inv) = right else {
        return None;
    };
    if inv.id.0 != "variable" {
        return None;
    }
    inv.arguments.iter().find_map(|a| match (&a.id, &a.rvalue) {
        (Some(id), RValue::Literal(Literal::String(s))) if id.0 == "label" => Some(s.as_str()),
        _ => None,
    })
}

/// Rewrite each f32 weight `w = variable(label = L)` of `proto` into
/// `w_int8 = variable(label = L)` (its tensor now int8), `w_scale = variable(label = L_scale)`,
/// `w_wide = tract_core_cast(w_int8, to = "f32")` and `w = mul(w_wide, w_scale)`.
fn store_weights_as_int8(
    proto: &mut ProtoModel,
    axes: &HashMap<String, usize>,
) -> TractResult<Int8Stored> {
    let mut stored = Int8Stored::default();
    let body = std::mem::take(&mut proto.doc.graph_def.body);
    let mut out: Vec<Assignment> = Vec::with_capacity(body.len());
    for a in body {
        let label = variable_label(&a.right).map(str::to_owned);
        let axis = label.as_ref().and_then(|l| axes.get(l)).copied();
        let weight = label
            .as_ref()
            .and_then(|l| proto.tensors.get(&Identifier(l.clone())))
            .filter(|t| axis.is_some_and(|axis| is_int8_weight(t, axis)))
            .cloned();
        let (Some(label), Some(weight), Some(axis), tract_nnef::ast::LValue::Identifier(id)) =
            (label, weight, axis, &a.left)
        else {
            out.push(a);
            continue;
        };
        let (q, scale) =
            quantize_per_channel(&weight, axis).with_context(|| format!("weight {label}"))?;
        let scale_label = format!("{label}_scale");
        let (q_id, scale_id, wide_id) = (
            format!("{}_int8", id.0),
            format!("{}_scale", id.0),
            format!("{}_wide", id.0),
        );
        ensure!(
            !proto.tensors.contains_key(&Identifier(scale_label.clone())),
            "a tensor is already labelled {scale_label}"
        );
        out.push(assignment(&q_id, a.right.clone().into()));
        out.push(assignment(
            &scale_id,
            tract_nnef::ast::RValue::Invocation(tract_nnef::ast::Invocation {
                id: "variable".into(),
                generic_type_name: Some(tract_nnef::ast::TypeName::Scalar),
                arguments: vec![
                    named_arg("label", string(&scale_label)),
                    named_arg("shape", ints(scale.shape())),
                ],
            })
            .into(),
        ));
        out.push(assignment(
            &wide_id,
            invocation(
                "tract_core_cast",
                &[ident(&q_id).into()],
                &[("to", datum_type(f32::datum_type()))],
            ),
        ));
        out.push(assignment(
            &id.0,
            invocation(
                "mul",
                &[ident(&wide_id).into(), ident(&scale_id).into()],
                &[],
            ),
        ));
        stored.tensors += 1;
        stored.elements += q.len();
        proto.tensors.insert(Identifier(label), q.into_arc_tensor());
        proto
            .tensors
            .insert(Identifier(scale_label), scale.into_arc_tensor());
    }
    proto.doc.graph_def.body = out;
    let core = (Identifier::from("tract_registry"), "tract_core".to_owned());
    if stored.tensors > 0 && !proto.doc.extension.contains(&core) {
        proto.doc.extension.push(core);
    }
    Ok(stored)
}

/// `value` as int8 along `axis`, one scale per index of `axis`: `q = round(w / s)`,
/// `s = max |w| / 127` over the slice (1 for an all-zero slice). Returns the int8 tensor and the
/// scales shaped to broadcast against it.
fn quantize_per_channel(value: &Tensor, axis: usize) -> TractResult<(Tensor, Tensor)> {
    let view = value.to_plain_array_view::<f32>()?;
    let channels = value.shape()[axis];
    let mut scales = vec![1f32; channels];
    for (c, s) in scales.iter_mut().enumerate() {
        let slice = view.index_axis(tract_ndarray::Axis(axis), c);
        let max_abs = slice.iter().fold(0f32, |m, w| m.max(w.abs()));
        ensure!(max_abs.is_finite(), "a weight is not finite");
        if max_abs > 0.0 {
            *s = max_abs / Q_MAX;
        }
    }
    // Logical (row-major) order, the order `from_shape` reads.
    let q: Vec<i8> = view
        .indexed_iter()
        .map(|(ix, w)| {
            let s = scales[ix[axis]];
            // In range by construction: |w / s| <= 127.
            (w / s).round().clamp(-Q_MAX, Q_MAX) as i8
        })
        .collect();
    let q = Tensor::from_shape(value.shape(), &q)?;
    let mut scale_shape = vec![1usize; value.rank()];
    scale_shape[axis] = channels;
    let scale = Tensor::from_shape(&scale_shape, &scales)?;
    Ok((q, scale))
}

#[cfg(test)]
mod tests {
    use super::super::test_graphs::{dat_sizes, model_adding};
    use super::*;

    const ROWS: usize = 4;
    const COLS: usize = 64;

    /// Rows of different ranges (row 2 all zero), so one scale per row is exercised.
    fn weights() -> Vec<f32> {
        (0..ROWS * COLS)
            .map(|i| {
                let (r, c) = (i / COLS, i % COLS);
                if r == 2 {
                    0.0
                } else {
                    (c as f32 - 31.5) * 0.01 * (1 + 5 * r) as f32
                }
            })
            .collect()
    }

    fn weight_tensor(w: &[f32]) -> TractResult<Tensor> {
        Tensor::from_shape(&[ROWS, COLS], w)
    }

    /// x + w: the tar stores w as int8 (one byte an element) and one scale per row, reads back
    /// and computes x + s_r * q in f32 bit for bit, with every weight within half a step of its
    /// f32 value.
    #[test]
    fn weights_are_stored_as_int8_and_widened_at_load() -> TractResult<()> {
        let w = weights();
        let nnef = tract_nnef::nnef();
        let (tar, stored) = write_tar(&nnef, &model_adding(weight_tensor(&w)?)?)?;
        assert_eq!(
            stored,
            Int8Stored {
                tensors: 1,
                elements: ROWS * COLS
            }
        );
        // A 128-byte header each: four f32 scales, 256 int8 weights.
        assert_eq!(
            dat_sizes(&tar)?,
            [128 + ROWS as u64 * 4, 128 + (ROWS * COLS) as u64]
        );
        let back = nnef.model_for_read(&mut tar.as_slice())?;
        let plan = back.into_optimized()?.into_runnable()?;
        let zeros = Tensor::zero::<f32>(&[ROWS, COLS])?;
        let out = plan.run(tvec![zeros.into_tvalue()])?;
        let got = out[0].try_as_plain_ram()?.as_slice::<f32>()?;
        for (i, (g, v)) in got.iter().zip(&w).enumerate() {
            let row = &w[i / COLS * COLS..][..COLS];
            let max_abs = row.iter().fold(0f32, |m, v| m.max(v.abs()));
            let s = if max_abs > 0.0 { max_abs / Q_MAX } else { 1.0 };
            let want = (v / s).round() * s;
            assert_eq!(g.to_bits(), want.to_bits(), "element {i}");
            assert!(
                (g - v).abs() <= s / 2.0 * (1.0 + 1e-6),
                "element {i}: {g} vs {v}"
            );
        }
        Ok(())
    }

    /// A weight of rank 1 (a bias, a norm's gain) stays f32.
    #[test]
    fn rank_one_constants_stay_f32() -> TractResult<()> {
        let model = model_adding(tensor1(&[0.5f32; COLS * 2]))?;
        let (_, stored) = write_tar(&tract_nnef::nnef(), &model)?;
        assert_eq!(stored, Int8Stored::default());
        Ok(())
    }

    /// A gain reshaped to `[1, C]` (one scale would cover every channel) and a table of points
    /// `[N, 2]` (two values a scale: one coordinate rounded by the other's magnitude) stay f32,
    /// as every value of them reads back bit for bit; `[N, 16]` is stored as int8.
    #[test]
    fn row_vectors_and_point_tables_stay_f32() -> TractResult<()> {
        let values: Vec<f32> = (0..COLS * 2).map(|i| 0.37 + i as f32 * 1e-3).collect();
        for shape in [[1, COLS * 2], [COLS, 2]] {
            let w = Tensor::from_shape(&shape, &values)?;
            let (tar, stored) = write_tar(&tract_nnef::nnef(), &model_adding(w.clone())?)?;
            assert_eq!(stored, Int8Stored::default(), "{shape:?}");
            let back = tract_nnef::nnef().model_for_read(&mut tar.as_slice())?;
            let plan = back.into_optimized()?.into_runnable()?;
            let out = plan.run(tvec![Tensor::zero::<f32>(&shape)?.into_tvalue()])?;
            let got = out[0].try_as_plain_ram()?.as_slice::<f32>()?;
            assert_eq!(got, values.as_slice(), "{shape:?}");
        }
        let w = Tensor::from_shape(&[COLS * 2 / 16, 16], &values)?;
        let (_, stored) = write_tar(&tract_nnef::nnef(), &model_adding(w)?)?;
        assert_eq!(stored.tensors, 1);
        Ok(())
    }
}
