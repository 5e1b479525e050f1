//! What a native product does to its finished sums besides the bias ([`Epilogue`]): the
//! description the ops that run the native product carry ([`crate::ops::conv_unfold::UnfoldConv`],
//! [`crate::ops::pointwise::PointwiseConv`], [`crate::ops::linear::PackedLinear`]) and the pass that
//! fills it in ([`crate::passes::epilogue`]) sets. A leaf: it imports the product and tract only, so the
//! ops and the pass that mutates them do not import each other both ways.

use tract_nnef::internal::*;

use crate::gemm;

/// The steps a native convolution takes after its bias.
#[derive(Clone, Copy, Debug, Default)]
pub struct Epilogue {
    /// A shortcut of the output's shape is added (the op's second input).
    pub residual: bool,
    /// `max(v, floor)` last.
    pub floor: Option<f32>,
}

impl PartialEq for Epilogue {
    fn eq(&self, other: &Self) -> bool {
        self.residual == other.residual
            && self.floor.map(f32::to_bits) == other.floor.map(f32::to_bits)
    }
}
impl Eq for Epilogue {}

impl Epilogue {
    /// Whether there is no step at all.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        !self.residual && self.floor.is_none()
    }

    /// The op's inputs: the map first, then the shortcut where there is one.
    #[must_use]
    pub fn inputs(&self) -> usize {
        1 + usize::from(self.residual)
    }

    /// The values of the shortcut among an op's `inputs`, checked against the op's `output`
    /// shape: `None` without a residual step.
    ///
    /// # Errors
    /// A missing shortcut, or one of another shape or type (the plan's, so a bug).
    pub fn shortcut<'a>(
        &self,
        inputs: &'a [TValue],
        output: &[usize],
    ) -> TractResult<Option<&'a [f32]>> {
        ensure!(
            inputs.len() == self.inputs(),
            "{} inputs, expected {}",
            inputs.len(),
            self.inputs()
        );
        if !self.residual {
            return Ok(None);
        }
        let r = &inputs[1];
        ensure!(
            r.shape() == output && r.datum_type() == f32::datum_type(),
            "shortcut {:?} {:?}, expected f32 {output:?}",
            r.datum_type(),
            r.shape()
        );
        Ok(Some(r.try_as_plain_ram()?.as_slice::<f32>()?))
    }

    /// The product's finish: `bias`, then `residual`'s values, then the floor.
    #[must_use]
    pub fn finish<'a>(
        &self,
        bias: gemm::Bias<'a>,
        residual: Option<&'a [f32]>,
    ) -> gemm::Finish<'a> {
        gemm::Finish {
            bias,
            residual,
            floor: self.floor,
        }
    }

    /// The op's output facts: `output` in f32, after checking the input facts.
    ///
    /// # Errors
    /// Inputs of another count, type or (shortcut) shape.
    pub fn output_facts(
        &self,
        inputs: &[&TypedFact],
        output: &[usize],
    ) -> TractResult<TVec<TypedFact>> {
        ensure!(inputs.len() == self.inputs());
        ensure!(inputs.iter().all(|f| f.datum_type == f32::datum_type()));
        if self.residual {
            ensure!(inputs[1].shape.as_concrete() == Some(output));
        }
        Ok(tvec!(f32::fact(output)))
    }
}
