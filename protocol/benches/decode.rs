//! Decode throughput of both links: `cargo bench -p scout-protocol`. Figures go in BENCHMARKS.md.

use divan::counter::{BytesCount, ItemsCount};
use divan::{Bencher, black_box};
use scout_protocol::serial::{self, StreamDecoder};
use scout_protocol::{CanFrame, can, candump};

const CAPTURE: &str = include_str!("../tests/fixtures/scout-v1-capture-2019.candump");

fn capture_frames() -> Vec<CanFrame> {
    CAPTURE
        .lines()
        .map(|line| candump::parse(line).expect("valid capture").frame)
        .collect()
}

fn main() {
    divan::main();
}

/// CAN: check and decode each frame of the real capture (2248 frames).
#[divan::bench]
fn can_decode(bencher: Bencher<'_, '_>) {
    let frames = capture_frames();
    bencher
        .counter(ItemsCount::new(frames.len()))
        .bench_local(|| {
            for frame in &frames {
                let _ = black_box(can::decode(black_box(frame)));
            }
        });
}

/// Serial: the capture re-encoded as one RS232 byte stream, through the streaming decoder.
#[divan::bench]
fn serial_stream_decode(bencher: Bencher<'_, '_>) {
    let stream: Vec<u8> = capture_frames()
        .iter()
        .map(|frame| can::decode(frame).expect("valid capture"))
        .flat_map(|counted| serial::encode(&counted.message, counted.count))
        .collect();
    bencher
        .counter(BytesCount::new(stream.len()))
        .bench_local(|| {
            let mut decoder = StreamDecoder::new();
            black_box(decoder.push_all(black_box(&stream)).count())
        });
}

/// candump text: parse the screen-format lines of the capture.
#[divan::bench]
fn candump_parse(bencher: Bencher<'_, '_>) {
    bencher
        .counter(BytesCount::new(CAPTURE.len()))
        .bench_local(|| {
            for line in CAPTURE.lines() {
                let _ = black_box(candump::parse(black_box(line)));
            }
        });
}
