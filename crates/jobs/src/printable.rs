//! Text from inputs made safe for a terminal. A recording's ids (rails,
//! applicators, sites, trains), a table's cells and the paths a user gives
//! reach error messages and summaries; a terminal would run their escape
//! sequences (`ESC ] 0;...BEL` retitles it, `ESC [2J` clears it), a
//! right-to-left override would reorder what is shown, and a 15 MB id would
//! make a 15 MB line. [`printable`] writes control and bidirectional
//! formatting characters as `\u{..}` and shortens every run of more than
//! [`LONGEST_WORD`] characters without a space to its start and its length.

use std::borrow::Cow;
use std::fmt::Write as _;

/// A word (characters between spaces) longer than this is shortened.
const LONGEST_WORD: usize = 256;
/// What is kept of a shortened word.
const KEPT: usize = 64;

/// Whether `c` must not reach a terminal as it is: a control character
/// (but a newline where lines are kept), or one that changes the direction
/// or joining of what follows (Unicode's bidirectional formatting
/// characters, zero-width marks).
fn hidden(c: char, lines: bool) -> bool {
    (c.is_control() && !(lines && c == '\n'))
        || matches!(c, '\u{200B}'..='\u{200F}' | '\u{202A}'..='\u{202E}' | '\u{2066}'..='\u{2069}' | '\u{061C}' | '\u{FEFF}')
}

/// `text` as a terminal may show it: newlines kept when `lines`, every
/// other control character escaped; long words shortened.
pub fn printable(text: &str, lines: bool) -> Cow<'_, str> {
    let long = text
        .split([' ', '\n'])
        .any(|w| w.len() > LONGEST_WORD && w.chars().count() > LONGEST_WORD);
    if !long && !text.chars().any(|c| hidden(c, lines)) {
        return Cow::Borrowed(text);
    }
    let mut out = String::with_capacity(text.len().min(1 << 16));
    let mut first = true;
    for line in text.split('\n') {
        if !first {
            out.push_str(if lines { "\n" } else { "\\u{a}" });
        }
        first = false;
        let mut first_word = true;
        for word in line.split(' ') {
            if !first_word {
                out.push(' ');
            }
            first_word = false;
            let count = word.chars().count();
            let shown: Box<dyn Iterator<Item = char>> = if count > LONGEST_WORD {
                Box::new(word.chars().take(KEPT))
            } else {
                Box::new(word.chars())
            };
            for c in shown {
                if hidden(c, lines) {
                    let _ = write!(out, "\\u{{{:x}}}", c as u32);
                } else {
                    out.push(c);
                }
            }
            if count > LONGEST_WORD {
                let _ = write!(out, "… ({} bytes in all)", word.len());
            }
        }
    }
    Cow::Owned(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escapes_what_a_terminal_would_run_and_shortens_what_would_flood_it() {
        assert!(matches!(
            printable("rail high: ok", false),
            Cow::Borrowed(_)
        ));
        assert_eq!(
            printable("rail \u{1b}]0;owned\u{7} and \u{1b}[2J", false),
            "rail \\u{1b}]0;owned\\u{7} and \\u{1b}[2J"
        );
        assert_eq!(printable("a\u{202E}b\0c", false), "a\\u{202e}b\\u{0}c");
        assert_eq!(printable("one\ntwo", true), "one\ntwo");
        assert_eq!(printable("one\ntwo", false), "one\\u{a}two");
        let id = "x".repeat(15_000_000);
        let message = format!("unknown rail {id}: in /train/passage");
        let line = printable(&message, false);
        assert_eq!(
            line,
            format!(
                "unknown rail {}… (15000001 bytes in all) in /train/passage",
                "x".repeat(64)
            )
        );
        // The word is what lies between spaces: the colon went with the id.
        // A long word of multi-byte characters is cut at a character.
        let wide = "é".repeat(300);
        assert!(printable(&wide, false).starts_with(&"é".repeat(64)));
    }
}
