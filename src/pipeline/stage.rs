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

/// Final output rows `a..`, to be finished: each row of a base window, and
/// of an accumulator added to it.
pub struct Output<'s> {
    /// The first row.
    pub a: usize,
    /// The base rows, from `a` on.
    pub base: Vec<&'s [f64]>,
    /// The accumulator's rows, where the method has one.
    pub acc: Option<Vec<&'s [f64]>>,
}

impl<'s> Output<'s> {
    /// Rows `a..b` of `base` (and `acc`).
    pub fn of(
        base: &'s RowWindow<f64>,
        acc: Option<&'s RowWindow<f64>>,
        (a, b): (usize, usize),
    ) -> Self {
        Output {
            a,
            base: (a..b).map(|y| base.get(y)).collect(),
            acc: acc.map(|acc| (a..b).map(|y| acc.get(y)).collect()),
        }
    }
}

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
    /// With `all_in` a stage may stop short, to hand its last rows over a
    /// few at a time rather than hold them all at once: the skeleton calls
    /// again, with no new rows, until every row is final (a call that
    /// makes none final ends the run with an error).
    fn advance(&mut self, input: &RowWindow<f32>, rows_in: usize, all_in: bool) -> usize;
    /// The first input row the stage will still read.
    fn input_needed(&self) -> usize;
    /// The unrounded values of final output rows `a..b`.
    fn output(&self, rows: (usize, usize)) -> Output<'_>;
    /// Output rows below `y` are written: release them.
    fn release(&mut self, y: usize);
    /// What the stage counted.
    fn counts(&self) -> MethodCounts;
    /// The windows it holds (the input window is the skeleton's).
    fn windows(&self) -> Vec<WindowUse>;
}
