//! The real chassis capture (tests/fixtures, BSD-3-Clause, see its README): every frame decodes.

use scout_protocol::sequence::{Continuity, SequenceTracker};
use scout_protocol::{ChassisState, ControlMode, Fault, Message, can, candump};

const CAPTURE: &str = include_str!("fixtures/scout-v1-capture-2019.candump");

#[test]
fn every_frame_of_the_capture_decodes_without_error_or_gap() {
    let mut tracker = SequenceTracker::new();
    let mut frames = 0;
    let mut gaps = 0;
    let mut statuses = Vec::new();
    for (number, line) in CAPTURE.lines().enumerate() {
        let record = candump::parse(line).unwrap_or_else(|e| panic!("line {}: {e}", number + 1));
        assert_eq!(record.interface, Some("can1"));
        let counted =
            can::decode(&record.frame).unwrap_or_else(|e| panic!("line {}: {e}", number + 1));
        frames += 1;
        if let Continuity::Gap { .. } | Continuity::Repeated =
            tracker.observe(counted.message.kind(), counted.count)
        {
            gaps += 1;
        }
        if let Message::SystemStatus(status) = counted.message {
            statuses.push(status);
        }
    }
    assert_eq!(frames, 2248);
    assert_eq!(gaps, 0);
    assert_eq!(tracker.lost(), 0);
    assert!(!statuses.is_empty());
    for status in statuses {
        assert_eq!(status.state, ChassisState::EStop);
        assert_eq!(status.control_mode, ControlMode::Rc);
        assert_eq!(status.battery_decivolts, 239);
        let expected = [
            Fault::Motor1CommFault,
            Fault::Motor2CommFault,
            Fault::Motor3CommFault,
            Fault::Motor4CommFault,
        ];
        assert_eq!(status.faults.iter().collect::<Vec<_>>(), expected);
    }
}

#[test]
fn compact_formatting_round_trips_the_capture() {
    for line in CAPTURE.lines() {
        let frame = candump::parse(line).expect("valid line").frame;
        let compact = candump::Compact(&frame).to_string();
        assert_eq!(candump::parse(&compact).expect("compact").frame, frame);
    }
}
