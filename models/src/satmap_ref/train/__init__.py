"""Training SatMap (MapTR v1 recipe) on a `satmap-dataset/1` folder, and predicting with the
trained weights.

Modules: `dataset` (reading the dataset folder), `sampler` (seeded, resumable frame order),
`targets` (GT polylines -> MapTR targets with permutation-equivalent shifts), `matcher`
(Hungarian matching), `losses` (focal, point L1, edge direction), `forward` (the model's stage
chain in training and prediction, both modes), `loop` (optimiser, schedule, checkpoints, log),
`predict` (MapTR results JSON). CLI: `python -m satmap_ref.train` and
`python -m satmap_ref.train.predict`."""
