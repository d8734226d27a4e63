//! The contract between the streaming skeleton ([`super::stream`]) and a
//! method's stage: what a stage is asked, and the windows it reports.

use super::counts::MethodCounts;
use super::window::RowWindow;
use crate::geometry::Halo;

/// A window a stage holds: its name, the most rows it held and the bytes of
/// one row (for the report's memory figures).
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct WindowUse {
    /// What it holds.
    pub name: &'static str,
    /// Most rows held at once.
    pub rows: usize,
    /// Bytes per row.
    pub row_bytes: usize,
}

/// The windows of final output rows: a base window and an accumulator added
/// to it.
pub type Output<'s> = (&'s RowWindow<f64>, Option<&'s RowWindow<f64>>);

/// Work a stage runs beside the books' loop ([`Stage::beside_books`]).
pub type Early<'s> = dyn FnOnce(&crate::trace::Span) + Send + 's;

/// A method's work on the rows, behind the skeleton.
pub trait Stage: Send {
    /// Rows the method reaches beyond the row it works on.
    fn halo(&self) -> Halo;
    /// Input rows `a..b` have just entered `input` (the books have taken
    /// them). A stage may alter them (the clamp foil cuts them) and compute
    /// what it keeps per input row.
    fn arrive(&mut self, input: &mut RowWindow<f32>, a: usize, b: usize);
    /// Go as far as `rows_in` input rows allow (`all_in`: the image is
    /// complete); returns the end of the output rows that are now final.
    fn advance(&mut self, input: &RowWindow<f32>, rows_in: usize, all_in: bool) -> usize;
    /// The first input row the stage will still read.
    fn input_needed(&self) -> usize;
    /// The unrounded values of final output rows: a base window and an
    /// accumulator added to it.
    fn output(&self) -> Output<'_>;
    /// Input rows `a..b` have just entered `input`, before the books take
    /// them: work on them that can run beside the books' loop (their ledger,
    /// the finishing of final rows), as tasks of the region it is given, and
    /// the windows the books finish from (one loop's end less a strip: a
    /// wake-up of many cores, docs/DESIGN.md, "The model's join"). None by
    /// default.
    fn beside_books<'s>(
        &'s mut self,
        _input: &'s RowWindow<f32>,
        _rows: (usize, usize),
    ) -> (Output<'s>, Option<Box<Early<'s>>>) {
        (self.output(), None)
    }
    /// Output rows below `y` are written: release them.
    fn release(&mut self, y: usize);
    /// What the stage counted.
    fn counts(&self) -> MethodCounts;
    /// The windows it holds (the input window is the skeleton's).
    fn windows(&self) -> Vec<WindowUse>;
}
