"""Fleet replays on Ray: many `satmap-sim drive` runs as Ray tasks, merged into one verdict.

- `drives`: what a fleet replays (synthetic world seeds, scenario folders) and the command line
  of one drive.
- `worker`: the Ray task (the binary and the bundle from the object store, cached per node by
  digest; one drive in a temporary folder; its outputs back as bytes).
- `merge`: the merged report (AP recomputed by `satmap-sim evaluate` from every drive's matches,
  latency percentiles over every step, degraded steps, the per-drive table, the worst pictures).
- `__main__`: the CLI, `python -m satmap_ref.fleet`.
"""
