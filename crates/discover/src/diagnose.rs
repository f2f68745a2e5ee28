//! Where the model and the measurements disagree: how much of the residual
//! variance each covariate explains, and an estimate of the measurement
//! noise that does not depend on the model being right.
//!
//! The measure is the correlation ratio
//! `eta² = Σ_b n_b (mean_b − mean)² / Σ_i (r_i − mean)²` of the residuals
//! grouped into bins of the covariate: its categories, or for a continuous
//! covariate its distinct values when there are at most [`MAX_BINS`] of
//! them, else deciles. Unknown values (NaN) form a bin of their own. eta²
//! sees any shape of dependence (a step at night, a bump near the
//! applicator), not only a straight line. Covariates with more bins explain
//! a little more by chance, so they are ranked by the adjusted value
//! `1 − (1 − eta²)(n − 1)/(n − k)` (k bins), which is about 0 for a
//! covariate the residual does not follow.

use serde::Serialize;

use super::data::{Covariate, Dataset, Values};
use tortwin_recording::BogiePosition;

/// Continuous covariates with at most this many distinct values are binned
/// by value; others by deciles.
pub(super) const MAX_BINS: usize = 10;

/// One covariate's share of the residual variance.
#[derive(Debug, Clone, Serialize)]
pub struct CovariateScore {
    pub name: String,
    pub description: String,
    pub eta2: f64,
    pub eta2_adjusted: f64,
    pub bins: usize,
    /// Per bin: label, count, mean residual.
    pub profile: Vec<BinMean>,
}

#[derive(Debug, Clone, Serialize)]
pub struct BinMean {
    pub bin: String,
    /// Representative covariate value (the bin's mean); NaN (null in
    /// JSON) for categories.
    pub x: f64,
    pub n: usize,
    pub mean_residual: f64,
}

/// The bins of a covariate: a bin index per row, and per bin its label and
/// representative x.
pub(super) struct Bins {
    pub(super) index: Vec<usize>,
    pub(super) labels: Vec<String>,
    pub(super) x: Vec<f64>,
}

pub(super) fn bins(c: &Covariate) -> Bins {
    match &c.values {
        Values::Categorical { labels, codes } => {
            let used: Vec<u32> = {
                let mut u = codes.clone();
                u.sort_unstable();
                u.dedup();
                u
            };
            let index = codes
                .iter()
                .map(|code| used.partition_point(|u| u < code))
                .collect();
            Bins {
                index,
                labels: used
                    .iter()
                    .map(|&u| {
                        labels
                            .get(u as usize)
                            .cloned()
                            .unwrap_or_else(|| u.to_string())
                    })
                    .collect(),
                x: vec![f64::NAN; used.len()],
            }
        }
        Values::Continuous(v) => {
            let mut finite: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
            finite.sort_unstable_by(f64::total_cmp);
            let mut distinct = finite.clone();
            distinct.dedup();
            // Upper edges of the bins (a value goes into the first bin whose
            // edge is >= it).
            let by_value = distinct.len() <= MAX_BINS;
            let edges: Vec<f64> = if by_value {
                distinct
            } else {
                let mut e: Vec<f64> = (1..=MAX_BINS)
                    .map(|q| {
                        let k = (q * finite.len()).div_ceil(MAX_BINS).saturating_sub(1);
                        finite[k.min(finite.len() - 1)]
                    })
                    .collect();
                e.dedup();
                e
            };
            if edges.is_empty() {
                // Nothing known: one bin.
                return Bins {
                    index: vec![0; v.len()],
                    labels: vec!["unknown".into()],
                    x: vec![f64::NAN],
                };
            }
            let unknown = edges.len();
            let index: Vec<usize> = v
                .iter()
                .map(|x| {
                    if x.is_finite() {
                        edges.partition_point(|e| e < x).min(unknown - 1)
                    } else {
                        unknown
                    }
                })
                .collect();
            let bins = edges.len() + usize::from(v.iter().any(|x| !x.is_finite()));
            let mut sum = vec![0.0; bins];
            let mut count = vec![0usize; bins];
            for (&b, &x) in index.iter().zip(v) {
                if x.is_finite() {
                    sum[b] += x;
                    count[b] += 1;
                }
            }
            let x: Vec<f64> = (0..bins)
                .map(|b| {
                    if count[b] > 0 {
                        sum[b] / count[b] as f64
                    } else {
                        f64::NAN
                    }
                })
                .collect();
            let mut labels: Vec<String> = Vec::with_capacity(bins);
            for (b, e) in edges.iter().enumerate() {
                labels.push(match b.checked_sub(1).map(|p| edges[p]) {
                    _ if by_value => short(*e),
                    None => format!("[{}, {}]", short(finite[0]), short(*e)),
                    Some(low) => format!("({}, {}]", short(low), short(*e)),
                });
            }
            if bins > edges.len() {
                labels.push("unknown".into());
            }
            Bins { index, labels, x }
        }
    }
}

fn short(v: f64) -> String {
    if v.abs() >= 100.0 {
        format!("{v:.0}")
    } else if v.abs() >= 1.0 {
        format!("{v:.2}")
    } else {
        format!("{v:.3}")
    }
}

/// eta² of `residual` over the bins of `c`.
///
/// Rows whose residual is not finite (gross outliers) are left out.
pub(super) fn score(c: &Covariate, residual: &[f64]) -> CovariateScore {
    let b = bins(c);
    let k = b.labels.len();
    let n = residual.iter().filter(|r| r.is_finite()).count();
    let mean = residual.iter().filter(|r| r.is_finite()).sum::<f64>() / n.max(1) as f64;
    let total: f64 = residual
        .iter()
        .filter(|r| r.is_finite())
        .map(|r| (r - mean).powi(2))
        .sum();
    let mut sum = vec![0.0; k];
    let mut count = vec![0usize; k];
    for (&i, &r) in b.index.iter().zip(residual) {
        if r.is_finite() {
            sum[i] += r;
            count[i] += 1;
        }
    }
    let between: f64 = (0..k)
        .filter(|&i| count[i] > 0)
        .map(|i| count[i] as f64 * (sum[i] / count[i] as f64 - mean).powi(2))
        .sum();
    let eta2 = if total > 0.0 { between / total } else { 0.0 };
    let eta2_adjusted = if n > k && k > 0 {
        1.0 - (1.0 - eta2) * (n as f64 - 1.0) / (n - k) as f64
    } else {
        eta2
    };
    CovariateScore {
        name: c.name.to_string(),
        description: c.description.to_string(),
        eta2,
        eta2_adjusted,
        bins: k,
        profile: (0..k)
            .filter(|&i| count[i] > 0)
            .map(|i| BinMean {
                bin: b.labels[i].clone(),
                x: b.x[i],
                n: count[i],
                mean_residual: sum[i] / count[i] as f64,
            })
            .collect(),
    }
}

/// Every covariate's score, the strongest first.
pub(super) fn rank(data: &Dataset, residual: &[f64]) -> Vec<CovariateScore> {
    let mut scores: Vec<CovariateScore> =
        data.covariates.iter().map(|c| score(c, residual)).collect();
    scores.sort_by(|a, b| b.eta2_adjusted.total_cmp(&a.eta2_adjusted));
    scores
}

/// The noise of the measurements, estimated without trusting the model:
/// consecutive axles of one train with the same bogie position (usually
/// two apart) measured at the same site, rail and quantity see almost the
/// same rail, so the difference of their residuals is mostly the two
/// measurements' noise: `sigma = sqrt(mean(diff²) / 2)`. Whatever the model
/// gets wrong changes little from one such axle to the next and mostly
/// cancels. `None` without such pairs.
pub(super) fn noise_estimate(data: &Dataset, residual: &[f64]) -> Option<f64> {
    let mut groups = neighbours(data);
    let mut sum = 0.0;
    let mut count = 0usize;
    for list in groups.values_mut() {
        list.retain(|&(_, k)| residual[k].is_finite());
        for pair in list.windows(2) {
            sum += (residual[pair[1].1] - residual[pair[0].1]).powi(2);
            count += 1;
        }
    }
    (count > 0).then(|| (sum / count as f64 / 2.0).sqrt())
}

/// A group of [`neighbours`]: train, site, rail, quantity, bogie position.
pub(super) type NeighbourKey = (usize, usize, usize, u8, u8);

/// The axle measurements that see almost the same rail: one group per
/// train, site, rail, quantity and bogie position, each a list of (axle,
/// row) in axle order. The noise estimate and the outlier screen compare
/// within these.
pub(super) fn neighbours(
    data: &Dataset,
) -> std::collections::BTreeMap<NeighbourKey, Vec<(usize, usize)>> {
    let mut groups: std::collections::BTreeMap<_, Vec<(usize, usize)>> =
        std::collections::BTreeMap::new();
    for (k, row) in data.rows.iter().enumerate() {
        let (Some(train), Some(axle)) = (row.train_seq, row.axle_index) else {
            continue;
        };
        let bogie = data
            .passages
            .get(train)
            .and_then(|p| p.bogies.get(axle))
            .map_or(2, |b| u8::from(*b == BogiePosition::Trailing));
        groups
            .entry((train, row.site, row.rail, row.quantity as u8, bogie))
            .or_default()
            .push((axle, k));
    }
    for list in groups.values_mut() {
        list.sort_unstable();
    }
    groups
}

#[cfg(test)]
mod tests {
    use super::*;

    fn continuous(v: Vec<f64>) -> Covariate {
        Covariate {
            name: "x",
            description: "x",
            values: Values::Continuous(v),
        }
    }

    #[test]
    fn eta2_is_one_when_the_residual_is_a_function_of_the_bins() {
        let c = Covariate {
            name: "c",
            description: "c",
            values: Values::Categorical {
                labels: vec!["a".into(), "b".into(), "c".into()],
                codes: (0..300).map(|i| i % 3).collect(),
            },
        };
        let r: Vec<f64> = (0..300).map(|i| [0.1, -0.2, 0.05][i % 3]).collect();
        let s = score(&c, &r);
        assert!((s.eta2 - 1.0).abs() < 1e-12);
        assert_eq!(s.bins, 3);
    }

    #[test]
    fn eta2_is_the_share_of_a_step_in_a_continuous_covariate() {
        // Half the rows at x < 50 carry +1, the others -1, plus a known
        // within-bin spread of ±1: between = 1, total = 2.
        let x: Vec<f64> = (0..1000).map(|i| (i % 100) as f64).collect();
        let r: Vec<f64> = (0..1000)
            .map(|i| {
                let step = if i % 100 < 50 { 1.0 } else { -1.0 };
                step + if (i / 100) % 2 == 0 { 1.0 } else { -1.0 }
            })
            .collect();
        let s = score(&continuous(x), &r);
        assert_eq!(s.bins, MAX_BINS, "deciles of 100 distinct values");
        assert!((s.eta2 - 0.5).abs() < 1e-12, "{}", s.eta2);
    }

    #[test]
    fn unknown_values_get_a_bin_of_their_own() {
        let x = vec![1.0, 2.0, f64::NAN, f64::NAN];
        let b = bins(&continuous(x));
        assert_eq!(b.labels, vec!["1.00", "2.00", "unknown"]);
        assert_eq!(b.index, vec![0, 1, 2, 2]);
    }
}
