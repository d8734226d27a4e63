//! The column tiles of an accumulator: tile `t` owns columns `t * tile ..`
//! of every channel of every row, so tiles can be written in parallel, each
//! pixel by one task, in an order that does not depend on the tile size.

use super::window::RowWindow;

/// The rows of `acc` (planar `[c][x]`, `w` columns per channel) cut into
/// column tiles of `tile`: entry `t` lists tile `t`'s slices row by row,
/// channel by channel (`nch` per row), from the window's first row.
pub fn column_tiles(
    acc: &mut RowWindow<f64>,
    w: usize,
    nch: usize,
    tile: usize,
) -> Vec<Vec<&mut [f64]>> {
    let (first, end) = (acc.first(), acc.end());
    let mut tiles: Vec<Vec<&mut [f64]>> = (0..w.div_ceil(tile))
        .map(|_| Vec::with_capacity((end - first) * nch))
        .collect();
    for row in acc.range_mut(first, end) {
        for ch in row.chunks_mut(w) {
            for (t, part) in ch.chunks_mut(tile).enumerate() {
                tiles[t].push(part);
            }
        }
    }
    tiles
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_column_of_every_channel_and_row_is_in_one_tile_in_order() {
        let (w, nch, rows, tile) = (10, 2, 3, 4);
        let mut acc = RowWindow::new(nch * w);
        for _ in 0..rows {
            acc.push(0.0);
        }
        let tiles = column_tiles(&mut acc, w, nch, tile);
        assert_eq!(tiles.len(), 3);
        for (t, parts) in tiles.into_iter().enumerate() {
            assert_eq!(parts.len(), rows * nch);
            let want = (w - t * tile).min(tile);
            assert!(parts.iter().all(|p| p.len() == want), "tile {t}");
            for (k, p) in parts.into_iter().enumerate() {
                p.fill((k * 100 + t) as f64);
            }
        }
        for r in 0..rows {
            let row = acc.get(r);
            for c in 0..nch {
                for x in 0..w {
                    assert_eq!(row[c * w + x], ((r * nch + c) * 100 + x / tile) as f64);
                }
            }
        }
    }
}
