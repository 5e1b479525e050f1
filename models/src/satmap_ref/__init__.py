"""Reference SatMap in PyTorch: configs, model, GKT look-up table and gather-sum reference,
staged ONNX export, golden vectors. `README.md` of `models/` says how the parts fit."""
