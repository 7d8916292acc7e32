//! Fuzzes what a browser sends `scout web`: the HTTP head of a request (and the WebSocket
//! admission on it) and a page's messages, in order, to its session.
#![no_main]

use std::time::Duration;

use libfuzzer_sys::fuzz_target;
use scout_web::access::{Role, User, Users, admit};
use scout_web::http::Head;
use scout_web::session::Session;

fuzz_target!(|input: &[u8]| {
    let users = Users::new(vec![User {
        name: "fuzz".into(),
        role: Role::Drive,
        token: "0123456789abcdef".into(),
    }])
    .expect("valid users");
    if let Ok((head, length)) = Head::parse(input) {
        assert!(length <= input.len());
        let _ = admit(&head, &users, "http");
    }
    // Each line a message, 7 ms apart.
    let mut session = Session::new(users.all()[0].clone(), Duration::ZERO);
    let text = String::from_utf8_lossy(input);
    for (at, line) in text.lines().enumerate() {
        let _ = session.handle_message(Duration::from_millis(7 * at as u64), line);
    }
    let _ = session.handle_close();
});
