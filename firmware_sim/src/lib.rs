//! Host-side simulation harness and tools for the SatMap ECU runtime.
