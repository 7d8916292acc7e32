//! Fuzzes what Foxglove clients send `scout foxglove` before the SDK's server sees it: the HTTP
//! head of a WebSocket handshake (and the server's answer) through the subprotocol front and
//! its origin check, and the body of a `/scout/estop` service call.
#![no_main]

use libfuzzer_sys::fuzz_target;
use scout_foxglove::live::reason_of;
use scout_foxglove::origin::OriginPolicy;
use scout_foxglove::subprotocol::{origin_of, rewrite_request, rewrite_response};

fuzz_target!(|input: &[u8]| {
    let _ = reason_of(input);
    if let Ok(head) = core::str::from_utf8(input) {
        let (request, _legacy) = rewrite_request(head);
        // What it sends on is a head with at most one protocol header, and nothing else lost.
        assert!(request.len() <= head.len() + 64);
        let _ = rewrite_response(head);
        let _ = OriginPolicy::new(&[]).check(origin_of(head));
    }
});
