//! The ECU tests, one module a concern, in one test binary (one link of the engine per target):
//! run on the host by `make test` and cross-built for aarch64 and run under qemu by
//! `make test-aarch64`, from the same source. Each names the kernel family it ran on, so a log
//! says which bits were proven where.

mod bad_data;
mod bev_storage;
mod determinism;
mod dropout;
mod lut_kernel;
mod precisions;
mod reference;
mod scenario;
mod threads;
