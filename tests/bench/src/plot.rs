//! PNG plots of a full run: the latency distributions of the state paths, and the tick
//! intervals over time in each condition. Text needs a TrueType font: DejaVu Sans from the
//! system (Debian's fonts-dejavu-core), or SCOUT_BENCH_FONT.

use std::path::{Path, PathBuf};

use anyhow::Context;
use plotters::prelude::*;

use crate::figures::Ticks;

const FONTS: [&str; 2] = [
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
];

fn register_font() -> anyhow::Result<()> {
    let path = std::env::var_os("SCOUT_BENCH_FONT")
        .map(PathBuf::from)
        .or_else(|| FONTS.iter().map(PathBuf::from).find(|path| path.exists()))
        .context("no TrueType font for the plots' text: install fonts-dejavu-core or set SCOUT_BENCH_FONT")?;
    let bytes = std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?;
    let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
    plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
        .map_err(|_| anyhow::anyhow!("{} is not a usable font", path.display()))?;
    Ok(())
}

const COLOURS: [RGBColor; 4] = [BLACK, BLUE, RED, GREEN];

pub fn draw(
    dir: &Path,
    paths: &[(String, Vec<f64>)],
    ticks: &[(String, Ticks)],
) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    register_font()?;
    latency(&dir.join("state-latency.png"), paths)?;
    intervals(&dir.join("tick-intervals.png"), ticks)?;
    Ok(())
}

fn plot_error<E: std::fmt::Debug>(error: E) -> anyhow::Error {
    anyhow::anyhow!("drawing a plot: {error:?}")
}

/// The cumulative distribution of each path's latency, log-scaled time.
fn latency(file: &Path, paths: &[(String, Vec<f64>)]) -> anyhow::Result<()> {
    let root = BitMapBackend::new(file, (1000, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_error)?;
    let max = paths
        .iter()
        .flat_map(|(_, samples)| samples.iter().copied())
        .fold(1.0, f64::max);
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "State latency: frame written to state seen (CDF)",
            ("sans-serif", 24),
        )
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d((10f64..max * 1.2).log_scale(), 0f64..1f64)
        .map_err(plot_error)?;
    chart
        .configure_mesh()
        .x_desc("latency, µs (log)")
        .y_desc("fraction of samples")
        .draw()
        .map_err(plot_error)?;
    for (index, (label, samples)) in paths.iter().enumerate() {
        let mut sorted = samples.clone();
        sorted.sort_by(f64::total_cmp);
        let n = sorted.len().max(1) as f64;
        let colour = COLOURS[index % COLOURS.len()];
        chart
            .draw_series(LineSeries::new(
                sorted
                    .iter()
                    .enumerate()
                    .map(|(i, x)| (x.max(10.0), (i + 1) as f64 / n)),
                colour.stroke_width(2),
            ))
            .map_err(plot_error)?
            .label(label.as_str())
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], colour.stroke_width(2)));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .position(SeriesLabelPosition::LowerRight)
        .draw()
        .map_err(plot_error)?;
    root.present().map_err(plot_error)?;
    Ok(())
}

/// Each 0x130 interval against its index, one panel a condition.
fn intervals(file: &Path, ticks: &[(String, Ticks)]) -> anyhow::Result<()> {
    let root =
        BitMapBackend::new(file, (1000, 300 * ticks.len().max(1) as u32)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_error)?;
    let panels = root.split_evenly((ticks.len().max(1), 1));
    for ((label, ticks), panel) in ticks.iter().zip(panels.iter()) {
        let top = ticks.intervals_ms.iter().copied().fold(25.0, f64::max) * 1.1;
        let mut chart = ChartBuilder::on(panel)
            .caption(
                format!("0x130 intervals at the chassis: {label}"),
                ("sans-serif", 20),
            )
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(55)
            .build_cartesian_2d(0usize..ticks.intervals_ms.len().max(1), 0f64..top)
            .map_err(plot_error)?;
        chart
            .configure_mesh()
            .x_desc("command")
            .y_desc("interval, ms")
            .draw()
            .map_err(plot_error)?;
        chart
            .draw_series(
                ticks
                    .intervals_ms
                    .iter()
                    .enumerate()
                    .map(|(i, ms)| Circle::new((i, *ms), 2, BLUE.filled())),
            )
            .map_err(plot_error)?;
    }
    root.present().map_err(plot_error)?;
    Ok(())
}
