# Selective static QOperator quantization: only Conv/MatMul nodes whose weight is an initializer
# (activation x activation attention MatMuls stay f32 -> avoids the tract DQ->Softmax->Q LUT bug),
# Gemm rewritten to MatMul+Add first (QGemm is com.microsoft and unsupported by tract).
import sys, os, numpy as np, onnx
from onnxruntime.quantization import quantize_static, QuantFormat, QuantType, CalibrationMethod
sys.path.insert(0, os.path.dirname(__file__))
from quant import Reader, gemm_to_matmul, B, Q, STAGES

def weight_nodes(path, skip=()):
    m = onnx.load(path); inits = {i.name for i in m.graph.initializer}
    consts = {o for n in m.graph.node if n.op_type == 'Constant' for o in n.output}
    return [n.name for n in m.graph.node if n.op_type in ('Conv', 'MatMul')
            and (n.input[1] in inits or n.input[1] in consts) and n.name not in skip]

def make(stage, tag, per_channel, act, sym, skip=()):
    g2m = Q + f'{stage}__gemm2mm.onnx'
    if not os.path.exists(g2m): gemm_to_matmul(B + stage + '.onnx', g2m)
    nodes = weight_nodes(g2m, skip)
    dst = Q + f'{stage}__{tag}.onnx'
    quantize_static(g2m, dst, Reader(stage), quant_format=QuantFormat.QOperator,
                    activation_type=act, weight_type=QuantType.QInt8, per_channel=per_channel,
                    op_types_to_quantize=['Conv', 'MatMul'], nodes_to_quantize=nodes,
                    calibrate_method=CalibrationMethod.MinMax,
                    extra_options={'ActivationSymmetric': sym})
    print(stage, tag, len(nodes), 'nodes quantized', flush=True)

if __name__ == '__main__':
    for st in (sys.argv[1:] or STAGES):
        make(st, 'sel_s8sym_pt', False, QuantType.QInt8, True)
        make(st, 'sel_u8_pt', False, QuantType.QUInt8, False)
        make(st, 'sel_u8_pc', True, QuantType.QUInt8, False)
    make('image_encoder', 'sel_s8sym_pt_nostem', False, QuantType.QInt8, True, skip=('/img_backbone/conv1/Conv',))
