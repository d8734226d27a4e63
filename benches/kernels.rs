//! Criterion benches of the hot paths: the base-width stencil (the ring sums
//! of Relation 14), the width search, the ep-box ring walk, and the whole
//! engine in memory for each method (the scatter of ep-gauss and ep-box is
//! the difference to `gauss`). `cargo bench --bench kernels`.

use criterion::{black_box, criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use epfilt::filter::ep_box::{Ring, Spp, StatsLayout, VarianceKind};
use epfilt::filter::ep_gauss::{EpGauss, Folded, LumImage};
use epfilt::{filter_in_memory, FilterParams, Grid, Method, PipelineConfig, StripLayout};

type Field = LumImage;

fn search(c: &mut Criterion) {
    let ep = EpGauss::new(3, 0.6, 16.0, 3.0, 0.25, 0.1);
    let mut g = c.benchmark_group("width_search");
    for mag in [10.0, 100.0, 1000.0, 1e5] {
        let f = Field::new(200, 200, ep.pad(), |x, y| {
            if (x, y) == (100, 100) {
                (8.0 + mag) / 9.0
            } else {
                1.0
            }
        });
        let xb = ep.xbar0(&f, 100, 100);
        g.bench_with_input(BenchmarkId::from_parameter(mag), &mag, |b, &mag| {
            b.iter(|| black_box(ep.search(&f, 100, 100, black_box(mag), xb)))
        });
    }
    // Real dynamic ranges: 9% of the pixels hold a firefly of 1e2..1e5
    // (log-uniform; 1% of S = 3 super-samples) over a smooth background, so
    // the average grows with the width as other fireflies enter it. One
    // iteration searches every firefly away from the borders.
    let (w, h) = (256usize, 256usize);
    let hash = |x: usize, y: usize| {
        let mut z = (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ (y as u64 + 17);
        z = (z ^ (z >> 31)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        (z ^ (z >> 29)) as f64 / u64::MAX as f64
    };
    let bg = |x: usize, y: usize| 0.5 + 0.3 * (x as f64 / 70.0).sin() * (y as f64 / 50.0).cos();
    let mag = |x: usize, y: usize| {
        let u = hash(x, y);
        (u < 0.09).then(|| 10f64.powf(2.0 + 3.0 * u / 0.09) * bg(x, y))
    };
    let f = Field::new(w, h, ep.pad(), |x, y| {
        (8.0 * bg(x, y) + mag(x, y).unwrap_or(bg(x, y))) / 9.0
    });
    let list: Vec<(usize, usize, f64, f64)> = (48..h - 48)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .filter_map(|(x, y)| mag(x, y).map(|m| (x, y, m, ep.xbar0(&f, x, y as i64))))
        .collect();
    g.throughput(Throughput::Elements(list.len() as u64));
    g.bench_function("dense 1e2..1e5", |b| {
        let mut fold = Folded::default();
        b.iter(|| {
            for &(x, y, m, xb) in &list {
                black_box(ep.search_in(&f, x, y, m, xb, &mut fold));
            }
        })
    });
    // The same with wide widths on the coarse grid (the default).
    let ep = ep.with_coarse(FilterParams::new(Method::EpGauss, 3).coarse_from);
    g.bench_function("dense 1e2..1e5 coarse", |b| {
        let mut fold = Folded::default();
        b.iter(|| {
            for &(x, y, m, xb) in &list {
                black_box(ep.search_in(&f, x, y, m, xb, &mut fold));
            }
        })
    });
    g.finish();
}

fn base_stencil(c: &mut Criterion) {
    let ep = EpGauss::new(3, 0.6, 16.0, 3.0, 0.25, 0.1);
    let f = Field::new(2048, 8, ep.pad(), |x, y| {
        1.0 + ((x * 31 + y * 17) % 7) as f64
    });
    let mut g = c.benchmark_group("base_stencil_row");
    g.throughput(Throughput::Elements(2048));
    g.bench_function("2048 px", |b| {
        b.iter(|| black_box(ep.xbar0_row(&f, 4, 2048)))
    });
    g.finish();
}

fn engine(c: &mut Criterion) {
    let (w, h, s) = (900, 600, 3);
    let mut img = Vec::with_capacity(w * h * 3);
    let mut k = 1u64;
    for y in 0..h {
        for ch in 0..3 {
            for x in 0..w {
                k = k
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let base = 0.6
                    + 0.3 * ((x as f32 * 0.01).sin() * (y as f32 * 0.013).cos())
                    + 0.05 * ch as f32;
                let fire = if (k >> 33) % 100 == 0 {
                    10f32.powf(1.0 + 2.0 * ((k >> 20) % 1000) as f32 / 1000.0)
                } else {
                    1.0
                };
                img.push(base * fire);
            }
        }
    }
    let job = StripLayout::new(
        Grid {
            in_w: w,
            in_h: h,
            s,
        },
        vec!["R".into(), "G".into(), "B".into()],
        vec![0.2126, 0.7152, 0.0722],
    );
    let mut g = c.benchmark_group("engine_900x600_s3_1pct_fireflies");
    g.throughput(Throughput::Elements((w * h) as u64));
    g.sample_size(20);
    for m in [
        Method::Box,
        Method::Gauss,
        Method::EpGauss,
        Method::Clamp,
        Method::Median,
        Method::AlphaTrim,
    ] {
        let p = FilterParams::new(m, s);
        g.bench_function(m.name(), |b| {
            b.iter(|| {
                black_box(
                    filter_in_memory(img.clone(), &job, &p, &PipelineConfig::default()).unwrap(),
                )
            })
        });
    }
    g.finish();
}

fn ring(c: &mut Criterion) {
    let r = Ring::new(16.0);
    let mut g = c.benchmark_group("ep_box_ring_prefix");
    g.bench_function("interior 400 px", |b| {
        b.iter(|| black_box(r.prefix(black_box(100), 100, 300, 200, 400)))
    });
    g.bench_function("corner 400 px", |b| {
        b.iter(|| black_box(r.prefix(black_box(0), 0, 300, 200, 400)))
    });
    g.finish();
}

/// ep-box on 600x400 pixels (9 spp mean + variance), 1% fireflies of 10x..1000x.
fn ep_box_engine(c: &mut Criterion) {
    let (w, h) = (600, 400);
    let mut img = Vec::with_capacity(w * h * 6);
    let mut k = 7u64;
    for y in 0..h {
        let mut row = vec![0.0f32; 6 * w];
        for x in 0..w {
            k = k
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let base = 0.6 + 0.3 * ((x as f32 * 0.01).sin() * (y as f32 * 0.013).cos());
            let hot = if (k >> 33) % 100 == 0 {
                10f32.powf(1.0 + 2.0 * ((k >> 20) % 1000) as f32 / 1000.0)
            } else {
                0.0
            };
            for c in 0..3 {
                // 8 samples at `base`, one at `base + hot`.
                row[c * w + x] = base + hot / 9.0;
                row[(3 + c) * w + x] = hot * hot / 9.0 + 1e-6;
            }
        }
        img.extend(row);
    }
    let mut job = StripLayout::new(
        Grid {
            in_w: w,
            in_h: h,
            s: 1,
        },
        vec!["R".into(), "G".into(), "B".into()],
        vec![0.2126, 0.7152, 0.0722],
    );
    job.aux = vec!["vR".into(), "vG".into(), "vB".into()];
    job.stats = Some(StatsLayout {
        variance: vec![3, 4, 5],
        kind: VarianceKind::Sample,
        mean_y: None,
        spp: Spp::Fixed(9.0),
    });
    let mut g = c.benchmark_group("ep_box_engine_600x400_1pct_fireflies");
    g.throughput(Throughput::Elements((w * h) as u64));
    g.sample_size(20);
    for r in [4.0, 16.0] {
        let mut p = FilterParams::new(Method::EpBox, 1);
        p.max_radius = r;
        p.ep_box.ltvis = Some(0.6 / 128.0);
        g.bench_with_input(BenchmarkId::new("max_radius", r), &r, |b, _| {
            b.iter(|| {
                black_box(
                    filter_in_memory(img.clone(), &job, &p, &PipelineConfig::default()).unwrap(),
                )
            })
        });
    }
    g.finish();
}

criterion_group!(benches, search, base_stencil, ring, engine, ep_box_engine);
criterion_main!(benches);
