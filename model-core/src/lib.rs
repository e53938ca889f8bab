//! The trueaxis core shared by the host tool and the firmware: everything the
//! two sides must agree on bit for bit — model evaluation (f32 and fixed
//! point, plus the f64 reference on the host), the binary table format and
//! the link protocol. `no_std`, no allocation, no `unsafe`.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![forbid(unsafe_code)]

pub mod link;
