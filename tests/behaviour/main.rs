//! Behaviour tests of epfilt, one binary with a module per theme.

mod common;
mod corpus;
mod energy;
mod exr_io;
mod invariance;
mod reference;
