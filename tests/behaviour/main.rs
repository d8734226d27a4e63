//! Behaviour tests of epfilt, one binary with a module per theme.

mod common;
mod energy;
mod invariance;
mod reference;
