//! Behaviour tests of epfilt, one binary with a module per theme.

mod band;
mod channels;
mod cli;
mod common;
mod corpus;
mod damaged;
mod data_safety;
mod defaults;
mod energy;
mod ep_box;
mod exr_io;
mod extremes;
mod farm;
mod features;
mod foils;
mod guides;
mod invariance;
mod parts;
mod pictures;
mod reference;
mod restore;
mod rgbe;
mod robust;
mod synth;
mod trace;
