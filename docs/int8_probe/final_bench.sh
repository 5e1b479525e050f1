#!/bin/bash
# Interleaved per-stage timing of f32 vs all quantized variants, default ISA and with AMX-int8 disabled.
# run from the repository root
for isa in default -amx-int8; do
for st in bev_encoder image_encoder satellite_encoder map_decoder bev_query; do
  ms=$(ls docs/int8_probe/q/${st}__*.onnx | grep -v gemm2mm | grep -v qop_u8_pc_gemm)
  if [ $isa = default ]; then env -u TRACT_CPU_ISA taskset -c 1 /tmp/tractpy/bin/python docs/int8_probe/tbench_multi.py $st 15 models/bundles/test/$st.onnx $ms
  else TRACT_CPU_ISA=$isa taskset -c 1 /tmp/tractpy/bin/python docs/int8_probe/tbench_multi.py $st 15 models/bundles/test/$st.onnx $ms; fi | sed "s/^{/{\"isa\": \"$isa\", /"
done; done
