# Generate quantized variants of each stage with onnxruntime.quantization. Run with /tmp/tractpy python.
import sys, os, numpy as np, onnx
from onnx import helper, numpy_helper
from onnxruntime.quantization import (quantize_static, quantize_dynamic, QuantFormat, QuantType,
                                      CalibrationDataReader, CalibrationMethod)
B = 'models/bundles/test/'
Q = 'docs/int8_probe/q/'; os.makedirs(Q, exist_ok=True)
inp = np.load('docs/int8_probe/inputs.npz')
STAGES = ['image_encoder', 'bev_query', 'bev_encoder', 'satellite_encoder', 'map_decoder']

def cal_list(stage):
    d = {}
    for k in inp.files:
        if k.startswith(f'cal/{stage}/'):
            _, _, i, n = k.split('/'); d.setdefault(int(i), {})[n] = inp[k]
    return [d[i] for i in sorted(d)]

class Reader(CalibrationDataReader):
    def __init__(self, stage): self.it = iter(cal_list(stage))
    def get_next(self): return next(self.it, None)

def gemm_to_matmul(src, dst):
    """Rewrite Gemm(A, B_const, C) (alpha=beta=1) into MatMul(A, B') + Add(C) so that the
    QOperator quantizer emits standard-domain QLinearMatMul instead of com.microsoft QGemm."""
    m = onnx.load(src); g = m.graph
    inits = {i.name: i for i in g.initializer}
    new_nodes = []
    for n in g.node:
        if n.op_type != 'Gemm' or n.input[1] not in inits:
            new_nodes.append(n); continue
        at = {a.name: helper.get_attribute_value(a) for a in n.attribute}
        if at.get('transA', 0): new_nodes.append(n); continue
        w = numpy_helper.to_array(inits[n.input[1]])
        if at.get('transB', 0): w = w.T.copy()
        w = (w * at.get('alpha', 1.0)).astype(np.float32)
        if len(n.input) > 2 and n.input[2] and at.get('beta', 1.0) != 1.0:
            assert n.input[2] in inits
            bn = n.input[2] + '_beta'
            g.initializer.append(numpy_helper.from_array((numpy_helper.to_array(inits[n.input[2]]) * at['beta']).astype(np.float32), bn))
            n.input[2] = bn
        wn = n.input[1] + '_mm'
        g.initializer.append(numpy_helper.from_array(w, wn))
        if len(n.input) > 2 and n.input[2]:
            mid = n.output[0] + '_mm'
            new_nodes.append(helper.make_node('MatMul', [n.input[0], wn], [mid], name=n.name + '_mm'))
            new_nodes.append(helper.make_node('Add', [mid, n.input[2]], [n.output[0]], name=n.name + '_bias'))
        else:
            new_nodes.append(helper.make_node('MatMul', [n.input[0], wn], [n.output[0]], name=n.name + '_mm'))
    del g.node[:]; g.node.extend(new_nodes)
    onnx.save(m, dst)

def variants(stage):
    src = B + stage + '.onnx'
    g2m = Q + f'{stage}__gemm2mm.onnx'; gemm_to_matmul(src, g2m)
    S = dict(calibrate_method=CalibrationMethod.MinMax)
    return {
      'qop_u8_pc':      (src, dict(quant_format=QuantFormat.QOperator, activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8, per_channel=True, op_types_to_quantize=['Conv','MatMul'], **S)),
      'qop_s8_pc':      (src, dict(quant_format=QuantFormat.QOperator, activation_type=QuantType.QInt8,  weight_type=QuantType.QInt8, per_channel=True, op_types_to_quantize=['Conv','MatMul'], **S)),
      'qop_u8_pc_gemm': (src, dict(quant_format=QuantFormat.QOperator, activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8, per_channel=True, op_types_to_quantize=['Conv','MatMul','Gemm'], **S)),
      'qop_u8_pt':      (src, dict(quant_format=QuantFormat.QOperator, activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8, per_channel=False, op_types_to_quantize=['Conv','MatMul'], **S)),
      'qop_u8_pc_g2m':  (g2m, dict(quant_format=QuantFormat.QOperator, activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8, per_channel=True, op_types_to_quantize=['Conv','MatMul'], **S)),
      'qop_u8_pt_g2m':  (g2m, dict(quant_format=QuantFormat.QOperator, activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8, per_channel=False, op_types_to_quantize=['Conv','MatMul'], **S)),
      'qop_s8_pt_g2m':  (g2m, dict(quant_format=QuantFormat.QOperator, activation_type=QuantType.QInt8, weight_type=QuantType.QInt8, per_channel=False, op_types_to_quantize=['Conv','MatMul'], **S)),
      'qop_s8sym_pt_g2m': (g2m, dict(quant_format=QuantFormat.QOperator, activation_type=QuantType.QInt8, weight_type=QuantType.QInt8, per_channel=False, op_types_to_quantize=['Conv','MatMul'], extra_options={'ActivationSymmetric': True}, **S)),
      'qdq_u8_pc':      (src, dict(quant_format=QuantFormat.QDQ, activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8, per_channel=True, op_types_to_quantize=['Conv','MatMul','Gemm'], **S)),
      'qdq_s8_pc':      (src, dict(quant_format=QuantFormat.QDQ, activation_type=QuantType.QInt8,  weight_type=QuantType.QInt8, per_channel=True, op_types_to_quantize=['Conv','MatMul','Gemm'], **S)),
      'dyn_s8':         (src, None),
      'dyn_u8':         (src, None),
      'dyn_s8_pt':      (src, None),
    }

if __name__ == '__main__':
    stages = sys.argv[1:] or STAGES
    only = os.environ.get('ONLY')
    for st in stages:
        for v, (src, kw) in variants(st).items():
            if only and v not in only.split(','): continue
            dst = Q + f'{st}__{v}.onnx'
            try:
                if kw is None:
                    wt = QuantType.QUInt8 if v.startswith('dyn_u8') else QuantType.QInt8
                    quantize_dynamic(src, dst, weight_type=wt, per_channel=not v.endswith('_pt'), op_types_to_quantize=['Conv','MatMul','Gemm'])
                else:
                    quantize_static(src, dst, Reader(st), **kw)
                m = onnx.load(dst)
                import collections
                c = collections.Counter((n.domain or '') + ':' + n.op_type for n in m.graph.node)
                q = {k: v for k, v in c.items() if any(s in k for s in ['Quant','QLinear','Integer','QGemm','Conv','MatMul','Gemm'])}
                print(st, v, 'OK', q, flush=True)
            except Exception as e:
                print(st, v, 'FAIL', type(e).__name__, str(e)[:200], flush=True)
