//! EXR input and output.
