//! Mutators: stacked random edits of a seed, for binary files (MCAP) and
//! for text (JSON, TOML, CSV). The randomness is the caller's seeded
//! generator, so a campaign is reproducible.

use rand::Rng;

/// Integers that break length fields and counts: edges of the unsigned and
/// signed widths, and sizes just past common limits.
const INTERESTING_U64: [u64; 14] = [
    0,
    1,
    0x7f,
    0xff,
    0x7fff,
    0xffff,
    0x7fff_ffff,
    0xffff_ffff,
    0x1_0000_0000,
    0xfd2d_0a28, // 4.25 GB, the allocation the issue saw
    1 << 40,
    i64::MAX as u64,
    1 << 63,
    u64::MAX,
];

/// Numbers for text fields: zero, signs, extremes, subnormals, non-finite
/// spellings, integers past 2^53 and 2^64, big counts.
const INTERESTING_NUMBERS: [&str; 22] = [
    "0",
    "-0",
    "-1",
    "1",
    "0.5",
    "1e-9",
    "1e-320",
    "1e308",
    "-1e308",
    "1e309",
    "NaN",
    "inf",
    "-inf",
    "9007199254740993",
    "18446744073709551615",
    "18446744073709551616",
    "-9223372036854775809",
    "4294967296",
    "1000000",
    "1e7",
    "65535",
    "2e9",
];

/// Characters that make or break structure in JSON, TOML and CSV.
const STRUCTURE: &[u8] = b"{}[]\",:=\n\r .-+e#'\\";

/// Applies 1 to 4 byte-level edits to `input`; `other` is another seed to
/// splice from.
pub fn bytes(rng: &mut impl Rng, input: &mut Vec<u8>, other: &[u8]) {
    for _ in 0..rng.random_range(1..=4) {
        byte_edit(rng, input, other);
    }
}

fn byte_edit(rng: &mut impl Rng, v: &mut Vec<u8>, other: &[u8]) {
    if v.is_empty() {
        v.push(rng.random());
        return;
    }
    let at = rng.random_range(0..v.len());
    match rng.random_range(0..10) {
        0 => v[at] ^= 1 << rng.random_range(0..8),
        1 => v[at] = [0u8, 0xff, 0x7f, 0x80, 1][rng.random_range(0..5)],
        2 => v[at] = v[at].wrapping_add(rng.random_range(1..=8)),
        3 | 4 => {
            // A little-endian integer over what may be a length, count or
            // time field.
            let width = [1usize, 2, 4, 8][rng.random_range(0..4)];
            let value = INTERESTING_U64[rng.random_range(0..INTERESTING_U64.len())];
            let end = (at + width).min(v.len());
            let le = value.to_le_bytes();
            v[at..end].copy_from_slice(&le[..end - at]);
        }
        5 => {
            let end = (at + rng.random_range(1..=64)).min(v.len());
            v.drain(at..end);
        }
        6 => {
            let end = (at + rng.random_range(1..=64)).min(v.len());
            let copy = v[at..end].to_vec();
            let to = rng.random_range(0..=v.len());
            v.splice(to..to, copy);
        }
        7 => {
            let n = rng.random_range(1..=16);
            let new: Vec<u8> = (0..n).map(|_| rng.random()).collect();
            v.splice(at..at, new);
        }
        8 if !other.is_empty() => {
            let from = rng.random_range(0..other.len());
            let end = (from + rng.random_range(1..=256)).min(other.len());
            let len = end - from;
            let stop = (at + len).min(v.len());
            v.splice(at..stop, other[from..end].iter().copied());
        }
        _ => v.truncate(at),
    }
}

/// Applies 1 to 4 text edits to `input`: numbers replaced by interesting
/// ones, characters and lines deleted, duplicated, swapped, structure
/// characters inserted, words copied from `other`.
pub fn text(rng: &mut impl Rng, input: &mut Vec<u8>, other: &[u8]) {
    for _ in 0..rng.random_range(1..=4) {
        text_edit(rng, input, other);
    }
}

fn text_edit(rng: &mut impl Rng, v: &mut Vec<u8>, other: &[u8]) {
    if v.is_empty() {
        v.extend_from_slice(INTERESTING_NUMBERS[0].as_bytes());
        return;
    }
    match rng.random_range(0..9) {
        0..=2 => {
            // A number (a run of digits, signs, dots and exponents) becomes
            // an interesting one.
            let numbers = spans(v, |b| b.is_ascii_digit() || b"+-.eE".contains(&b));
            if let Some(&(s, e)) = pick(rng, &numbers) {
                let new = INTERESTING_NUMBERS[rng.random_range(0..INTERESTING_NUMBERS.len())];
                v.splice(s..e, new.bytes());
            }
        }
        3 => {
            let lines = spans(v, |b| b != b'\n');
            if let Some(&(s, e)) = pick(rng, &lines) {
                v.drain(s..(e + 1).min(v.len()));
            }
        }
        4 => {
            let lines = spans(v, |b| b != b'\n');
            if let Some(&(s, e)) = pick(rng, &lines) {
                let mut line = v[s..e].to_vec();
                line.push(b'\n');
                let to = lines[rng.random_range(0..lines.len())].0;
                v.splice(to..to, line);
            }
        }
        5 => {
            let at = rng.random_range(0..=v.len());
            let c = STRUCTURE[rng.random_range(0..STRUCTURE.len())];
            v.insert(at, c);
        }
        6 => {
            let at = rng.random_range(0..v.len());
            let end = (at + rng.random_range(1..=8)).min(v.len());
            v.drain(at..end);
        }
        7 => {
            // A word of another seed in place of a word of this one (keys,
            // names, enum values).
            let words = spans(v, |b| b.is_ascii_alphanumeric() || b == b'_');
            let theirs = spans(other, |b| b.is_ascii_alphanumeric() || b == b'_');
            if let (Some(&(s, e)), Some(&(os, oe))) = (pick(rng, &words), pick(rng, &theirs)) {
                v.splice(s..e, other[os..oe].iter().copied());
            }
        }
        _ => byte_edit(rng, v, other),
    }
}

/// Maximal runs of bytes for which `keep` holds, as (start, end).
fn spans(v: &[u8], keep: impl Fn(u8) -> bool) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut start = None;
    for (i, &b) in v.iter().enumerate() {
        match (keep(b), start) {
            (true, None) => start = Some(i),
            (false, Some(s)) => {
                out.push((s, i));
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        out.push((s, v.len()));
    }
    out
}

fn pick<'a, T>(rng: &mut impl Rng, items: &'a [T]) -> Option<&'a T> {
    (!items.is_empty()).then(|| &items[rng.random_range(0..items.len())])
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn the_same_seed_gives_the_same_mutants_and_they_differ_from_the_input() {
        let seed = br#"{"speed_mps": 12.5, "axles": [{"offset_m": 0}]}"#.to_vec();
        let run = |s| {
            let mut rng = ChaCha8Rng::seed_from_u64(s);
            (0..50)
                .map(|_| {
                    let mut v = seed.clone();
                    text(&mut rng, &mut v, b"other words 1 2");
                    v
                })
                .collect::<Vec<_>>()
        };
        assert_eq!(run(7), run(7));
        let changed = run(7).iter().filter(|m| **m != seed).count();
        assert!(changed >= 45, "{changed} of 50 mutants differ");
    }

    #[test]
    fn numbers_become_interesting_ones() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let seen: std::collections::HashSet<Vec<u8>> = (0..400)
            .map(|_| {
                let mut v = b"x = 12.5".to_vec();
                text_edit(&mut rng, &mut v, b"");
                v
            })
            .collect();
        assert!(seen.contains(b"x = 1e308".as_slice()));
        assert!(seen.contains(b"x = NaN".as_slice()));
    }
}
