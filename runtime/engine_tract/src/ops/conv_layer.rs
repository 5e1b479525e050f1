//! A convolution as the native passes read it off its `Conv` node ([`conv_layer_at`]): what the
//! f32 [`crate::ops::conv_unfold::UnfoldConv`] and the int8
//! [`crate::ops::quant_conv::QuantConv`] passes (and the calibration's probes) take, by one rule.

use tract_nnef::internal::*;
use tract_nnef::tract_core::ops::cnn::Conv;
use tract_nnef::tract_core::ops::nn::DataFormat;

use crate::ops::unfold::Unfold;

/// A convolution the native passes take, read off its node: one group, NCHW over two spatial
/// axes (or CHW), batch 1, f32, constant weights and bias.
#[derive(Clone, Debug)]
pub struct ConvLayer {
    /// Its patches.
    pub unfold: Unfold,
    /// Whether input and output carry a batch axis of 1.
    pub batch_axis: bool,
    /// The input map.
    pub x: OutletId,
    /// The weights, OIHW.
    pub kernel: Arc<Tensor>,
    /// One bias an output channel.
    pub bias: Vec<f32>,
}

impl ConvLayer {
    /// Output channels.
    pub fn out_channels(&self) -> usize {
        self.bias.len()
    }
}

/// Node `id` as a [`ConvLayer`], or `None` when it is not one.
///
/// # Errors
/// tract refusing a fact (an inconsistent model).
pub fn conv_layer_at(model: &TypedModel, id: usize) -> TractResult<Option<ConvLayer>> {
    let node = model.node(id);
    let Some(conv) = node.op_as::<Conv>() else {
        return Ok(None);
    };
    if conv.q_params.is_some()
        || conv.group != 1
        || !matches!(
            conv.pool_spec.data_format,
            DataFormat::NCHW | DataFormat::CHW
        )
        || conv.pool_spec.kernel_shape.len() != 2
    {
        return Ok(None);
    }
    let facts: Vec<TypedFact> = model.node_input_facts(id)?.into_iter().cloned().collect();
    if facts.len() != 3 || facts[0].datum_type != f32::datum_type() {
        return Ok(None);
    }
    let Some(xs) = facts[0].shape.as_concrete() else {
        return Ok(None);
    };
    let (Some(kernel), Some(bias)) = (facts[1].konst.clone(), facts[2].konst.clone()) else {
        return Ok(None);
    };
    let batch_axis = conv.pool_spec.data_format == DataFormat::NCHW;
    let (ci, h, w) = match *xs {
        [1, c, h, w] if batch_axis => (c, h, w),
        [c, h, w] if !batch_axis => (c, h, w),
        _ => return Ok(None),
    };
    let co = conv.output_channels();
    let ks = &conv.pool_spec.kernel_shape;
    let (kh, kw) = (ks[0], ks[1]);
    if kernel.shape() != [co, ci, kh, kw] || kernel.datum_type() != f32::datum_type() {
        return Ok(None);
    }
    let Some(unfold) = Unfold::of_pool(&conv.pool_spec, [ci, h, w]) else {
        return Ok(None);
    };
    if bias.datum_type() != f32::datum_type() {
        return Ok(None);
    }
    let bias_plain = bias.try_as_plain_ram()?;
    let bias_all = bias_plain.as_slice::<f32>()?;
    let bias: Vec<f32> = if bias.rank() == 0 {
        vec![bias_all[0]; co]
    } else if bias.shape() == [co] {
        bias_all.to_vec()
    } else {
        return Ok(None);
    };
    Ok(Some(ConvLayer {
        unfold,
        batch_axis,
        x: node.inputs[0],
        kernel,
        bias,
    }))
}
