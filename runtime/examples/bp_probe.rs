use satmap_runtime::engine_tract::batched::native_batched;
use std::time::Instant;
use tract_nnef::prelude::*;
use tract_nnef::tract_core::ops::einsum::EinSum;
fn main() -> TractResult<()> {
    for (expr, sx, sy) in [
        (
            "mak,nak->amn",
            vec![2000usize, 4, 64],
            vec![2000usize, 4, 64],
        ),
        ("amk,kan->man", vec![4, 2000, 2000], vec![2000, 4, 64]),
    ] {
        let mut model = TypedModel::default();
        let x = model.add_source("x", f32::fact(&sx))?;
        let y = model.add_source("y", f32::fact(&sy))?;
        let es = EinSum {
            axes: expr.parse()?,
            operating_dt: f32::datum_type(),
            q_params: None,
        };
        let z = model.wire_node("mm", es, &[x, y])?;
        model.select_output_outlets(&z)?;
        let model = model.into_decluttered()?;
        let lx: usize = sx.iter().product();
        let ly: usize = sy.iter().product();
        let inputs = tvec![
            Tensor::from_shape(&sx, &vec![0.5f32; lx])?.into_tvalue(),
            Tensor::from_shape(&sy, &vec![0.25f32; ly])?.into_tvalue()
        ];
        for native in [false, true] {
            let m = if native {
                native_batched(model.clone())?.0
            } else {
                model.clone()
            };
            let plan = m.into_optimized()?.into_runnable()?;
            plan.run(inputs.clone())?;
            let mut best = f64::MAX;
            for _ in 0..5 {
                let t = Instant::now();
                plan.run(inputs.clone())?;
                best = best.min(t.elapsed().as_secs_f64());
            }
            println!("{expr} native={native}: {:.1} ms", best * 1e3);
        }
    }
    Ok(())
}
