//! The session token: 128 random bits from the operating system, written as 32 lowercase hex
//! digits, compared in constant time.

use crate::error::{Result, ViewError};

/// A 128-bit secret that every HTTP and WebSocket request must carry (`?token=…`).
#[derive(Clone, PartialEq, Eq)]
pub struct Token([u8; 16]);

impl std::fmt::Debug for Token {
    /// Never prints the secret.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Token(…)")
    }
}

impl Token {
    /// A fresh token from the operating system's random source (`getrandom`).
    pub fn random() -> Result<Token> {
        let mut bytes = [0u8; 16];
        getrandom::fill(&mut bytes).map_err(|e| ViewError::Random(e.to_string()))?;
        Ok(Token(bytes))
    }

    /// A token with the given bytes (tests; a front end that shares one token between servers).
    pub fn from_bytes(bytes: [u8; 16]) -> Token {
        Token(bytes)
    }

    /// The 32 lowercase hex digits that go in URLs.
    pub fn hex(&self) -> String {
        self.0.iter().map(|b| format!("{b:02x}")).collect()
    }

    /// Whether `candidate` is this token's hex form (either case). The comparison of the bytes
    /// takes the same time wherever they differ (an OR of XORs over all 16 bytes, no early
    /// exit), so response times tell an attacker nothing about a guess; only the length (32) is
    /// checked first, and it is public.
    pub fn matches(&self, candidate: &str) -> bool {
        let Some(bytes) = parse_hex(candidate) else {
            return false;
        };
        constant_time_eq(&self.0, &bytes)
    }
}

/// 32 hex digits as 16 bytes; `None` for any other text.
fn parse_hex(s: &str) -> Option<[u8; 16]> {
    let s = s.as_bytes();
    if s.len() != 32 {
        return None;
    }
    let mut out = [0u8; 16];
    let mut bad = 0u8;
    for (n, pair) in s.chunks_exact(2).enumerate() {
        let (hi, hi_ok) = hex_digit(pair[0]);
        let (lo, lo_ok) = hex_digit(pair[1]);
        bad |= !hi_ok as u8 | !lo_ok as u8;
        out[n] = hi << 4 | lo;
    }
    (bad == 0).then_some(out)
}

/// The value of an ASCII hex digit and whether it is one, without branching on the digit.
fn hex_digit(c: u8) -> (u8, bool) {
    let digit = c.wrapping_sub(b'0');
    let lower = (c | 0x20).wrapping_sub(b'a');
    let is_digit = digit < 10;
    let is_letter = lower < 6;
    let value = (digit & (is_digit as u8).wrapping_neg())
        | (lower.wrapping_add(10) & (is_letter as u8).wrapping_neg());
    (value, is_digit | is_letter)
}

/// `a == b` in time independent of where they differ.
fn constant_time_eq(a: &[u8; 16], b: &[u8; 16]) -> bool {
    let mut diff = 0u8;
    for k in 0..16 {
        diff |= a[k] ^ b[k];
    }
    std::hint::black_box(diff) == 0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_are_random_and_round_trip_through_hex() {
        let a = Token::random().unwrap();
        let b = Token::random().unwrap();
        assert_ne!(a, b);
        let hex = a.hex();
        assert_eq!(hex.len(), 32);
        assert!(
            hex.bytes()
                .all(|c| c.is_ascii_hexdigit() && !c.is_ascii_uppercase())
        );
        assert!(a.matches(&hex));
        assert!(a.matches(&hex.to_ascii_uppercase()));
        assert!(!b.matches(&hex));
        assert_eq!(format!("{a:?}"), "Token(…)");
    }

    #[test]
    fn near_misses_and_malformed_tokens_are_refused() {
        let t = Token::from_bytes([0xab; 16]);
        let good = "ab".repeat(16);
        assert!(t.matches(&good));
        for k in 0..32 {
            // One digit off, at every position.
            let mut s = good.clone().into_bytes();
            s[k] = if s[k] == b'a' { b'c' } else { b'a' };
            assert!(!t.matches(std::str::from_utf8(&s).unwrap()), "digit {k}");
        }
        for bad in [
            "",
            &good[..31],
            &format!("{good}0"),
            &format!("{}g", &good[..31]),
            &format!("{} ", &good[..31]),
            &format!("{}é", &good[..30]),
        ] {
            assert!(!t.matches(bad), "{bad:?}");
        }
    }

    #[test]
    fn hex_digits_decode_like_the_standard_library() {
        for c in 0..=255u8 {
            let (v, ok) = hex_digit(c);
            let std = (c as char).to_digit(16);
            assert_eq!(ok, std.is_some(), "{c}");
            if let Some(d) = std {
                assert_eq!(v as u32, d, "{c}");
            }
        }
    }

    #[test]
    fn equal_only_when_every_byte_is() {
        let a = [7u8; 16];
        for k in 0..16 {
            let mut b = a;
            b[k] ^= 1 << (k % 8);
            assert!(!constant_time_eq(&a, &b));
        }
        assert!(constant_time_eq(&a, &a.clone()));
    }
}
