//! msreg firmware: the estimator on a Cortex-M4F, with the QEMU mps2-an386 board as the
//! reference target.
//!
//! The library holds what the binaries share: the embedded sensor sequence (an analytic
//! trajectory sampled in `f32`, [`scenario`]), the self-test that runs the filter over it
//! ([`selftest`]), the joint layout's sequence and self-test ([`joint`]), the measuring
//! tools (stack painting, SysTick instruction clock), and the serial link: the CMSDK UART driver ([`uart`], [`ring`]) and the protocol session
//! ([`session`]) of the `link` binary with the filters it runs ([`filter`]).
//! Everything is `no_std` and allocation-free.
#![no_std]
#![warn(missing_docs)]

pub mod filter;
pub mod generator_check;
pub mod joint;
pub mod noise;
pub mod propagation;
pub mod ring;
pub mod scenario;
pub mod selftest;
pub mod session;
pub mod stack;
pub mod ticks;
pub mod trajectory;
pub mod uart;
