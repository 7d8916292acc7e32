//! Fuzzes the stop endpoint's datagrams, which any local process may send the gateway: the
//! request parser (a stop is never refused, anything else is refused with a reason), the reply
//! parser clients run on what comes back, and the peer-name mapping of remote stops.
#![no_main]

use libfuzzer_sys::fuzz_target;
use scout_interface::remote::peer_client_name;
use scout_interface::stop_socket::{self, StopReply};

fuzz_target!(|input: &[u8]| {
    match stop_socket::parse(input) {
        // What parses emits a datagram that parses to the same request.
        Ok(request) => {
            let again = stop_socket::parse(&request.emit()).expect("an emitted datagram parses");
            let whole = input.len() == stop_socket::request::LEN
                && input[stop_socket::request::VERSION] == scout_interface::LAYOUT_VERSION as u8;
            if whole {
                assert_eq!(again.ask, request.ask);
            }
        }
        Err(error) => assert!(!error.to_string().is_empty()),
    }
    let _ = StopReply::parse(input);
    if let Ok(peer) = core::str::from_utf8(input)
        && !peer.is_empty()
    {
        let name = peer_client_name(peer);
        assert!(name.len() <= 32 && name.is_ascii());
    }
});
