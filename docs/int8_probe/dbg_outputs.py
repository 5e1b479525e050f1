# Compare intermediate tensors between ORT and tract on a quantized model: python dbg_outputs.py model.onnx stage name1,name2,...
import sys, numpy as np, onnx, onnxruntime as ort, tract
from onnx import helper, TensorProto
p, st, names = sys.argv[1], sys.argv[2], sys.argv[3].split(',')
m = onnx.load(p)
inf = onnx.shape_inference.infer_shapes(m)
vi = {v.name: v for v in list(inf.graph.value_info) + list(inf.graph.output) + list(inf.graph.input)}
del m.graph.output[:]
for n in names:
    m.graph.output.append(vi[n] if n in vi else helper.make_tensor_value_info(n, TensorProto.UINT8, None))
onnx.save(m, '/tmp/dbg.onnx')
inp = np.load('docs/int8_probe/inputs.npz')
so = ort.SessionOptions(); so.intra_op_num_threads = 1
s = ort.InferenceSession('/tmp/dbg.onnx', so)
feeds = {i.name: inp[f'eval/{st}/{i.name}'] for i in s.get_inputs()}
o = s.run(None, feeds)
im = tract.onnx().load('/tmp/dbg.onnx')
order = [im.input_name(i) for i in range(im.input_count())]
r = im.into_model().into_runnable().run([feeds[k] for k in order])
for n, a, b in zip(names, o, r):
    b = b.to_numpy()
    d = np.abs(a.astype(np.float64) - b.astype(np.float64))
    print(f'{n}: {a.dtype}{a.shape} vs {b.dtype}{b.shape} maxdiff={d.max():.4g} frac_diff={(d>0).mean():.4g} ort_range=({a.min()},{a.max()})')
