#![no_main]
//! Fuzz target: the viewer's HTTP request heads (`volsplat_view::http::parse_head` and the
//! token, host and origin checks): never a panic, and no request without the token is let in.

use libfuzzer_sys::fuzz_target;
use volsplat_view::http::{HostRule, check, parse_head};
use volsplat_view::token::Token;

fuzz_target!(|data: &[u8]| {
    let Ok(Some(head)) = parse_head(data) else {
        return;
    };
    let token = Token::from_bytes([0x3c; 16]);
    for rule in [HostRule::Loopback, HostRule::Any] {
        if check(&head, &token, &rule).is_ok() {
            assert!(head.token.as_deref().is_some_and(|t| token.matches(t)));
        }
    }
});
