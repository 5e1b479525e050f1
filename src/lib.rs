//! Root package of the workspace. It holds no code of its own: its `tests/` folder holds the
//! integration tests that span `satmap-runtime` and `satmap-sim` (goldens, determinism, replays).
