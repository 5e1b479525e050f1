"""One stage of the committed `test` folder bundle on onnxruntime, `repeats` times, on its reference
inputs: the program targets/ort_insns.sh counts under the emulator beside our engine's
(tests/ecu/examples/stage_insns.rs). Standalone on purpose: it runs in an aarch64 Python that
holds onnxruntime, numpy and safetensors only (not the satmap_ref package and its torch).

    python ort_stage.py BUNDLE_DIR STAGE REPEATS
"""

import hashlib
import sys
from pathlib import Path

import numpy as np
import onnxruntime as ort
from safetensors.numpy import load_file


def main(bundle: Path, stage: str, repeats: int) -> int:
    options = ort.SessionOptions()
    # One thread, no spinning, sequential: the count is of the work, not of idle workers.
    options.intra_op_num_threads = 1
    options.inter_op_num_threads = 1
    options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    options.add_session_config_entry("session.intra_op.allow_spinning", "0")
    session = ort.InferenceSession(
        str(bundle / f"{stage}.onnx"), options, providers=["CPUExecutionProvider"]
    )
    reference = load_file(str(bundle / "reference.safetensors"))
    feeds = {}
    for spec in session.get_inputs():
        value = reference[f"{stage}.{spec.name}"]
        feeds[spec.name] = value.reshape([d for d in spec.shape])
    outputs = []
    for _ in range(repeats):
        outputs = session.run(None, feeds)
    digest = hashlib.sha256(b"".join(np.ascontiguousarray(o).tobytes() for o in outputs))
    print(f"{stage} x{repeats} onnxruntime {ort.__version__} digest={digest.hexdigest()[:16]}")
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 4:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    sys.exit(main(Path(sys.argv[1]), sys.argv[2], int(sys.argv[3])))
