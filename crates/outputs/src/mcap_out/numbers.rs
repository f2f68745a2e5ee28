//! The numbers of `/twin/field`, rounded to the precision the data has and
//! written as JSON text straight from the rounded integer.
//!
//! A field snapshot is about 2 000 numbers; in a year's replay they were a
//! tenth of the output thread's time in serde_json's float printer (the
//! shortest digits that read back to the double), which works out the
//! digits of a double it knows nothing about. A rounded number is an integer
//! `units` and a power of ten, so its shortest text is that integer's digits
//! with the decimal point put in: [`push`] writes exactly what serde_json
//! writes for the rounded double, and hands every number it cannot show to
//! be so (not finite, too large, too many decimals) to serde_json itself.

use super::{MASS_DIGITS, MASS_FLOOR_MG, MG_PER_KG, MU_DECIMALS};

/// How a number of `/twin/field` is rounded.
#[derive(Debug, Clone, Copy)]
pub(super) enum Precision {
    /// To this many decimals.
    Decimals(i32),
    /// Scaled by `factor`, to `digits` significant digits; below `floor`, 0.
    Significant {
        factor: f64,
        digits: i32,
        floor: f64,
    },
}

/// A number rounded: `value` is `units` x 10^-`decimals`, computed as the
/// nearest double to it.
#[derive(Debug, Clone, Copy)]
struct Rounding {
    value: f64,
    /// An integer (a double with no fraction; NaN for NaN).
    units: f64,
    /// Negative: to tens, hundreds, ...
    decimals: i32,
}

impl Precision {
    /// mu and adhesion: [`MU_DECIMALS`] decimals.
    pub(super) const MU: Precision = Precision::Decimals(MU_DECIMALS);

    /// The product masses, kg in, mg out: [`MASS_DIGITS`] significant
    /// digits, 0 below [`MASS_FLOOR_MG`].
    pub(super) const MASS_MG: Precision = Precision::Significant {
        factor: MG_PER_KG,
        digits: MASS_DIGITS,
        floor: MASS_FLOOR_MG,
    };

    /// `x` rounded. Rounding divides by an exact power of ten, so the
    /// result is the double nearest the decimal and JSON prints it short.
    #[cfg(test)]
    pub(super) fn round(self, x: f64) -> f64 {
        self.rounding(x).value
    }

    fn rounding(self, x: f64) -> Rounding {
        match self {
            Precision::Decimals(decimals) => round_decimals(x, decimals),
            Precision::Significant {
                factor,
                digits,
                floor,
            } => {
                let x = x * factor;
                if x.abs() < floor {
                    return Rounding {
                        value: 0.0,
                        units: 0.0,
                        decimals: 0,
                    };
                }
                round_decimals(x, digits - 1 - magnitude(x.abs()))
            }
        }
    }
}

/// `a.log10().floor() as i32`, without the logarithm where the answer is
/// plain: a number further than a relative 1e-12 from every power of ten
/// lies between two of them whose logarithms are integers more than 4e-13
/// away from its own, and `log10` (within an ulp, 4e-16 here) cannot round
/// across them. Near a power of ten, and outside 1e-29..1e29, it is
/// `log10`'s own answer.
fn magnitude(a: f64) -> i32 {
    const NEAR: f64 = 1.0 + 1e-12;
    if a.is_finite() && (1e-29..1e29).contains(&a) {
        // floor(e2 log10 2) from the binary exponent, then corrected.
        let e2 = ((a.to_bits() >> 52) & 0x7ff) as i32 - 1023;
        let mut k = ((e2 * 78_913) >> 18).clamp(-29, 28);
        while k < 28 && pow10(k + 1) <= a {
            k += 1;
        }
        while k > -29 && pow10(k) > a {
            k -= 1;
        }
        let (below, above) = (pow10(k), pow10(k + 1));
        if below <= a && a > below * NEAR && a * NEAR < above {
            return k;
        }
    }
    a.log10().floor() as i32
}

/// The double nearest 10^k, for k from -30 to 30 (exact from 0 to 22).
fn pow10(k: i32) -> f64 {
    const POW10: [f64; 61] = [
        1e-30, 1e-29, 1e-28, 1e-27, 1e-26, 1e-25, 1e-24, 1e-23, 1e-22, 1e-21, 1e-20, 1e-19, 1e-18,
        1e-17, 1e-16, 1e-15, 1e-14, 1e-13, 1e-12, 1e-11, 1e-10, 1e-9, 1e-8, 1e-7, 1e-6, 1e-5, 1e-4,
        1e-3, 1e-2, 1e-1, 1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13,
        1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22, 1e23, 1e24, 1e25, 1e26, 1e27, 1e28,
        1e29, 1e30,
    ];
    POW10[(k + 30) as usize]
}

/// `10f64.powi(d)` for `d` >= 0: from the table where it is exact (each
/// product of the powers of ten up to 10^22 is exact, so `powi` gives
/// these bits too), `powi` above.
fn scale(d: i32) -> f64 {
    if (0..=22).contains(&d) {
        pow10(d)
    } else {
        10f64.powi(d)
    }
}

/// `x` to `decimals` decimals (negative: to tens, hundreds, ...).
fn round_decimals(x: f64, decimals: i32) -> Rounding {
    if decimals >= 0 {
        let scale = scale(decimals);
        let units = (x * scale).round();
        Rounding {
            value: units / scale,
            units,
            decimals,
        }
    } else {
        let scale = scale(-decimals);
        let units = (x / scale).round();
        Rounding {
            value: units * scale,
            units,
            decimals,
        }
    }
}

/// Appends `x` rounded by `precision` as serde_json writes the rounded
/// double (`null` if it is not finite).
///
/// Why the digits of `units` are the shortest text: with `decimals` = k
/// from 0 to [`MAX_DECIMALS`], `value` is `units / 10^k` correctly rounded
/// (both exact doubles), so the decimal D = units x 10^-k reads back to it;
/// any other decimal with as few digits differs from D by at least 10^-k,
/// more than the spacing of doubles below [`MAX_VALUE`] (2^-22 < 10^-6), so
/// it reads back to another double: D trimmed of its trailing zeros is the
/// one shortest text. With k < 0, `value` is the integer units x 10^-k
/// exactly (below 2^53). From 10^-5 to below 10^16 serde_json writes it
/// without an exponent, as [`push`] does; smaller ones are its own.
pub(super) fn push(buf: &mut Vec<u8>, x: f64, precision: Precision) -> serde_json::Result<()> {
    let r = precision.rounding(x);
    let plain = r.value.is_finite()
        && r.value.abs() < MAX_VALUE
        && (r.value == 0.0 || r.value.abs() >= MIN_VALUE)
        && r.units.abs() < MAX_UNITS
        && (MIN_DECIMALS..=MAX_DECIMALS).contains(&r.decimals);
    if !plain {
        return serde_json::to_writer(buf, &r.value);
    }
    if r.value.is_sign_negative() {
        buf.push(b'-');
    }
    // An integer below 10^15: exact in u64.
    let mut units = r.units.abs() as u64;
    let mut decimals = r.decimals;
    while decimals > 0 && units != 0 && units.is_multiple_of(10) {
        units /= 10;
        decimals -= 1;
    }
    if units == 0 {
        decimals = 0;
    }
    let mut text = itoa::Buffer::new();
    let digits = text.format(units).as_bytes();
    if decimals <= 0 {
        // 123 x 10^2 -> 12300.0
        buf.extend_from_slice(digits);
        buf.resize(buf.len() + decimals.unsigned_abs() as usize, b'0');
        buf.extend_from_slice(b".0");
    } else {
        let decimals = decimals as usize;
        if digits.len() > decimals {
            // 1234 x 10^-2 -> 12.34
            let (whole, fraction) = digits.split_at(digits.len() - decimals);
            buf.extend_from_slice(whole);
            buf.push(b'.');
            buf.extend_from_slice(fraction);
        } else {
            // 12 x 10^-4 -> 0.0012
            buf.extend_from_slice(b"0.");
            buf.resize(buf.len() + decimals - digits.len(), b'0');
            buf.extend_from_slice(digits);
        }
    }
    Ok(())
}

/// Appends `xs` rounded by `precision` as a JSON array.
pub(super) fn push_array(
    buf: &mut Vec<u8>,
    xs: &[f64],
    precision: Precision,
) -> serde_json::Result<()> {
    buf.push(b'[');
    for (i, &x) in xs.iter().enumerate() {
        if i > 0 {
            buf.push(b',');
        }
        push(buf, x, precision)?;
    }
    buf.push(b']');
    Ok(())
}

/// The largest magnitude [`push`] writes itself (the spacing of doubles
/// below it is under 10^-6).
const MAX_VALUE: f64 = 1e9;
/// The smallest magnitude but zero that serde_json writes without an
/// exponent.
const MIN_VALUE: f64 = 1e-5;
/// The largest rounded integer it writes itself (exact in a double).
const MAX_UNITS: f64 = 1e15;
const MAX_DECIMALS: i32 = 6;
const MIN_DECIMALS: i32 = -15;

#[cfg(test)]
mod tests {
    use super::*;

    /// xorshift from `seed`: the same numbers every run.
    fn xorshift(mut state: u64) -> impl FnMut() -> u64 {
        move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        }
    }

    /// A draw in [0, 1) from 53 of its bits.
    fn unit(bits: u64) -> f64 {
        (bits >> 11) as f64 / (1u64 << 53) as f64
    }

    fn serde_text(x: f64, p: Precision) -> String {
        serde_json::to_string(&p.round(x)).unwrap()
    }

    fn our_text(x: f64, p: Precision) -> String {
        let mut buf = Vec::new();
        push(&mut buf, x, p).unwrap();
        String::from_utf8(buf).unwrap()
    }

    fn precisions() -> Vec<Precision> {
        let mut all: Vec<Precision> = (-3..=9).map(Precision::Decimals).collect();
        all.push(Precision::MASS_MG);
        all.push(Precision::Significant {
            factor: 1.0,
            digits: 7,
            floor: 1e-300,
        });
        all
    }

    /// Every number written as serde_json writes the rounded double: at the
    /// edges (zero of both signs, halves, powers of ten, the limits of the
    /// plain path, not finite) and at random magnitudes from 1e-12 to 1e18.
    /// It fails when the decimal point, the trailing zeros, the sign of
    /// zero or the exponent form are got wrong (tried).
    #[test]
    fn numbers_are_written_as_serde_json_writes_the_rounded_double() {
        let mut edges = vec![
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.5,
            0.05,
            0.00005,
            -0.00004,
            1e-5,
            1e-6,
            1e-7,
            0.58,
            0.3826,
            0.1 + 0.2,
            99.99995,
            999_999_999.4,
            999_999_999.6,
            1e9,
            1e15,
            1e16,
            123_456_789_012_345.6,
            f64::MAX,
            f64::MIN_POSITIVE,
            5e-324,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        for e in -12..=18 {
            edges.push(10f64.powi(e));
            edges.push(-(10f64.powi(e)));
            edges.push(0.5 * 10f64.powi(e));
        }
        let mut next = xorshift(0x9e37_79b9_7f4a_7c15);
        let mut random = Vec::new();
        for _ in 0..200_000 {
            let mantissa = unit(next());
            let exponent = (next() % 31) as i32 - 12;
            let sign = if next().is_multiple_of(4) { -1.0 } else { 1.0 };
            random.push(sign * mantissa * 10f64.powi(exponent));
        }
        for p in precisions() {
            for &x in edges.iter().chain(&random) {
                assert_eq!(our_text(x, p), serde_text(x, p), "{x:e} {p:?}");
            }
        }
    }

    /// The magnitude without the logarithm is the logarithm's, at random
    /// over 60 decades and at every power of ten and its neighbours (where
    /// `log10` rounds up to the integer); the table's powers are `powi`'s.
    /// It fails when the nearness guard is left out (tried).
    #[test]
    fn magnitudes_and_scales_are_those_of_log10_and_powi() {
        let mut next = xorshift(0x2545_f491_4f6c_dd1d);
        let mut values = Vec::new();
        for _ in 0..1_000_000 {
            values.push(10f64.powf(70.0 * unit(next()) - 35.0));
        }
        for k in -35..=35 {
            let p: f64 = format!("1e{k}").parse().unwrap();
            let mut up = p;
            let mut down = p;
            for _ in 0..2_000 {
                values.extend([up, down]);
                up = f64::from_bits(up.to_bits() + 1);
                down = f64::from_bits(down.to_bits() - 1);
            }
        }
        values.extend([
            0.0,
            5e-324,
            f64::MIN_POSITIVE,
            f64::MAX,
            f64::INFINITY,
            f64::NAN,
        ]);
        for a in values {
            assert_eq!(magnitude(a), a.log10().floor() as i32, "{a:e}");
        }
        for d in 0..=40 {
            assert_eq!(scale(d).to_bits(), 10f64.powi(d).to_bits(), "{d}");
        }
    }

    #[test]
    fn an_array_is_the_numbers_between_brackets() {
        let mut buf = Vec::new();
        push_array(
            &mut buf,
            &[0.123_456, f64::NAN, -2.0],
            Precision::Decimals(4),
        )
        .unwrap();
        assert_eq!(String::from_utf8(buf).unwrap(), "[0.1235,null,-2.0]");
        let mut buf = Vec::new();
        push_array(&mut buf, &[], Precision::Decimals(4)).unwrap();
        assert_eq!(buf, b"[]");
    }
}
