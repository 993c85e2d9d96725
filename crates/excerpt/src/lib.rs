//! Short excerpts of input for error messages. An error names the file, line and field and
//! quotes what it refuses, but never all of it: a multi-megabyte cell, line or key must not
//! travel into a reply, a log line or a database (issue 21). Every error type of bemcal prints
//! its message through [`shorten`]; a quoted value can be cut at its source with [`excerpt`].

#![deny(missing_docs)]

use std::borrow::Cow;

/// Longest excerpt of a refused input quoted in an error (bytes).
pub const EXCERPT_BYTES: usize = 200;

/// Longest message an error prints (bytes): its words, the location and an excerpt.
pub const MESSAGE_BYTES: usize = 600;

/// `text` cut to at most `max` bytes at a character boundary; when cut, the end says how many
/// bytes were left out.
pub fn excerpt(text: &str, max: usize) -> Cow<'_, str> {
    if text.len() <= max {
        return text.into();
    }
    let end = floor_boundary(text, max);
    format!("{}... ({} more bytes)", &text[..end], text.len() - end).into()
}

/// A message of at most about [`MESSAGE_BYTES`]: a longer one keeps its beginning (where the
/// location and the refused value start) and its end (what was expected), and says how much of
/// the middle was left out.
pub fn shorten(message: &str) -> Cow<'_, str> {
    if message.len() <= MESSAGE_BYTES {
        return message.into();
    }
    let head = floor_boundary(message, MESSAGE_BYTES * 3 / 5);
    let mut tail = message.len() - MESSAGE_BYTES / 3;
    while !message.is_char_boundary(tail) {
        tail += 1;
    }
    format!(
        "{} [... {} bytes left out ...] {}",
        &message[..head],
        tail - head,
        &message[tail..]
    )
    .into()
}

fn floor_boundary(text: &str, max: usize) -> usize {
    let mut end = max.min(text.len());
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    end
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_excerpt_is_cut_at_a_character_boundary_and_says_what_was_left_out() {
        assert_eq!(excerpt("short", 10), "short");
        let long = "é".repeat(1000);
        assert_eq!(excerpt(&long, 5), "éé... (1996 more bytes)");
        assert!(excerpt(&"x".repeat(3 << 20), EXCERPT_BYTES).len() < EXCERPT_BYTES + 30);
    }

    #[test]
    fn a_long_message_keeps_its_location_and_what_was_expected() {
        let m = format!(
            "meters.csv:12: column 'kWh': value '{}' is not a number (expected kWh)",
            "9".repeat(100_000)
        );
        let s = shorten(&m);
        assert!(s.len() <= MESSAGE_BYTES + 40, "{}", s.len());
        assert!(s.starts_with("meters.csv:12: column 'kWh': value '999"));
        assert!(s.ends_with("is not a number (expected kWh)"));
        assert!(s.contains("bytes left out"));
        assert_eq!(shorten("short"), "short");
        let wide = "é".repeat(2_000);
        assert!(shorten(&wide).len() < MESSAGE_BYTES + 40);
    }
}
