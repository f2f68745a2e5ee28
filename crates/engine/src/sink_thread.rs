//! A sink on a thread of its own: the engine's thread copies what it
//! publishes (a few kB a train) and goes on stepping while the file sinks
//! encode it (JSON and zstd for MCAP, Arrow for rerun). The sink sees the
//! same calls in the same order as it would on the engine's thread, so it
//! writes the same files.
//!
//! Calls cross in batches, through the workspace's one batched hand-over
//! (`tortwin_handover`; a wake-up per measurement would cost the engine more
//! than the encoding saves). Pulses and measurements, most of the calls,
//! cross without their names (applicator, site, rail, train): the thread
//! keeps its own copy of each, given once and again only when it changes
//! ([`Names`]). A pulse's two names were two strings allocated on the
//! engine's thread and freed on this one, a measurement's three `Arc`s'
//! counts written by both threads, their cache lines going back and forth.
//!
//! An error of the sink stops its thread; the engine gets that error at its next call (or at `finish`), as it would
//! have at the failing call itself, only a little later: nothing is renamed
//! into place before `finish` succeeds. Dropping a [`SinkThread`] waits for
//! the sink to be dropped, so a failed run's temporary files are gone when
//! the run returns.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;

use tortwin_handover::{Filler, Taker};

use tortwin_recording::Quantity;

use crate::sink::{
    Alert, Event, FieldSnapshot, LineWheels, MeasurementOutput, PulseEvent, RunSummary,
    SectionInfo, Sink, SinkError, SinkResult, TrainEvent, WheelContacts,
};
use crate::Readout;

/// Calls in one hand-over.
const BATCH: usize = 512;
/// A batch is also handed over once the arrays its calls own reach this
/// many bytes: on a section at the grid limit (200 000 points) one field
/// snapshot holds 6.4 MB and one wheel's contacts 1.6 MB, and 512 of them
/// held at once took the replay to 2-3 GB.
const BATCH_BYTES: usize = 8 << 20;
/// Batches in flight. With [`BATCH_BYTES`], the calls waiting for the
/// output hold at most `(QUEUE + 1) * (BATCH_BYTES + the largest call)`:
/// 132 MB at the grid limit, whatever the recording's length.
const QUEUE: usize = 8;

/// What crosses to the thread: a call, or a pulse or measurement without
/// its names.
enum Call {
    Event(Event<'static>),
    Pulse(PulseCall),
    Measurement(MeasurementCall),
}

/// A name as it crosses: `None` when the thread already holds it (the last
/// one given for its index).
type NewName = Option<Box<str>>;

/// A [`PulseEvent`] without its names.
struct PulseCall {
    log_time_ns: u64,
    applicator: usize,
    applicator_id: NewName,
    rail: usize,
    rail_name: NewName,
    mass_kg: f64,
}

/// A [`MeasurementOutput`] without its names.
struct MeasurementCall {
    log_time_ns: u64,
    index_in_file: u64,
    site: usize,
    site_id: NewName,
    rail: usize,
    rail_name: NewName,
    quantity: Quantity,
    /// `None` for no train (`rail_mu`).
    train_id: Option<NewName>,
    axle_index: Option<usize>,
    measured: f64,
    simulated: f64,
    readout: Option<Box<Readout>>,
}

/// The names one side of the thread holds: the last given for each
/// applicator, site and rail index, and the last train's id (at index 0 of
/// `train`). The engine's side keeps them to compare (`Box<str>`), the
/// thread's to hand out (`Arc<str>`, counted on that thread only).
struct Names<T> {
    applicators: Vec<Option<T>>,
    sites: Vec<Option<T>>,
    rails: Vec<Option<T>>,
    train: Vec<Option<T>>,
}

impl<T> Default for Names<T> {
    fn default() -> Self {
        Self {
            applicators: Vec::new(),
            sites: Vec::new(),
            rails: Vec::new(),
            train: Vec::new(),
        }
    }
}

/// `name` as it crosses for index `k`: `None` when `sent[k]` is it already,
/// else the text, which `sent[k]` keeps from now on.
fn new_name(sent: &mut Vec<Option<Box<str>>>, k: usize, name: &str) -> NewName {
    if sent.get(k).and_then(Option::as_deref) == Some(name) {
        return None;
    }
    if sent.len() <= k {
        sent.resize(k + 1, None);
    }
    sent[k] = Some(name.into());
    Some(name.into())
}

/// The thread's copy of the name of index `k`, replaced first by `new`
/// when one crossed.
fn known_name<'a>(
    known: &'a mut Vec<Option<Arc<str>>>,
    k: usize,
    new: NewName,
    what: &str,
) -> Result<&'a Arc<str>, SinkError> {
    if let Some(name) = new {
        if known.len() <= k {
            known.resize(k + 1, None);
        }
        known[k] = Some(Arc::from(name));
    }
    known
        .get(k)
        .and_then(Option::as_ref)
        .ok_or_else(|| format!("the output thread was never given the name of {what} {k}").into())
}

impl Names<Box<str>> {
    fn pulse(&mut self, p: &PulseEvent<'_>) -> PulseCall {
        PulseCall {
            log_time_ns: p.log_time_ns,
            applicator: p.applicator,
            applicator_id: new_name(&mut self.applicators, p.applicator, &p.applicator_id),
            rail: p.rail,
            rail_name: new_name(&mut self.rails, p.rail, &p.rail_name),
            mass_kg: p.mass_kg,
        }
    }

    fn measurement(&mut self, m: &MeasurementOutput) -> MeasurementCall {
        let train_id = m
            .train_id
            .as_deref()
            .map(|id| new_name(&mut self.train, 0, id));
        MeasurementCall {
            log_time_ns: m.log_time_ns,
            index_in_file: m.index_in_file,
            site: m.site,
            site_id: new_name(&mut self.sites, m.site, &m.site_id),
            rail: m.rail,
            rail_name: new_name(&mut self.rails, m.rail, &m.rail_name),
            quantity: m.quantity,
            train_id,
            axle_index: m.axle_index,
            measured: m.measured,
            simulated: m.simulated,
            readout: m.readout.clone(),
        }
    }
}

impl Names<Arc<str>> {
    fn send_pulse<S: Sink>(&mut self, p: PulseCall, sink: &mut S) -> SinkResult {
        let applicator_id = known_name(
            &mut self.applicators,
            p.applicator,
            p.applicator_id,
            "applicator",
        )?;
        let rail_name = known_name(&mut self.rails, p.rail, p.rail_name, "rail")?;
        sink.pulse(&PulseEvent {
            log_time_ns: p.log_time_ns,
            applicator: p.applicator,
            applicator_id: (&**applicator_id).into(),
            rail: p.rail,
            rail_name: (&**rail_name).into(),
            mass_kg: p.mass_kg,
        })
    }

    fn send_measurement<S: Sink>(&mut self, m: MeasurementCall, sink: &mut S) -> SinkResult {
        let train_id = match m.train_id {
            Some(new) => Some(Arc::clone(known_name(&mut self.train, 0, new, "train")?)),
            None => None,
        };
        let site_id = Arc::clone(known_name(&mut self.sites, m.site, m.site_id, "site")?);
        let rail_name = Arc::clone(known_name(&mut self.rails, m.rail, m.rail_name, "rail")?);
        sink.measurement(&MeasurementOutput {
            log_time_ns: m.log_time_ns,
            index_in_file: m.index_in_file,
            site_id,
            site: m.site,
            rail_name,
            rail: m.rail,
            quantity: m.quantity,
            train_id,
            axle_index: m.axle_index,
            measured: m.measured,
            simulated: m.simulated,
            readout: m.readout,
        })
    }
}

/// A [`Sink`] that runs another on a thread of its own.
pub struct SinkThread {
    to_thread: Filler<Vec<Call>>,
    /// The names the thread holds, as the engine's side compares them.
    names: Names<Box<str>>,
    failed: Arc<AtomicBool>,
    thread: Option<JoinHandle<SinkResult>>,
    /// The bytes the arrays of the batch's calls hold.
    batch_bytes: usize,
}

impl SinkThread {
    /// Starts `sink` on a thread named `name`; with `behind`, the thread runs
    /// behind the engine ([`tortwin_handover::behind_the_engine`]: a batch
    /// replay's outputs, unless they weigh as much as the engine).
    pub fn spawn<S: Sink + Send + 'static>(
        name: &str,
        sink: S,
        behind: bool,
    ) -> std::io::Result<Self> {
        let (to_thread, calls) = tortwin_handover::channel::<Vec<Call>>(QUEUE);
        let failed = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&failed);
        let thread = std::thread::Builder::new()
            .name(name.to_owned())
            .spawn(move || {
                if behind {
                    tortwin_handover::behind_the_engine();
                }
                let result = run(sink, &calls);
                if result.is_err() {
                    flag.store(true, Ordering::Release);
                }
                result
            })?;
        Ok(Self {
            to_thread,
            names: Names::default(),
            failed,
            thread: Some(thread),
            batch_bytes: 0,
        })
    }

    /// Hands `event`, owned, to the thread (in a batch).
    fn push(&mut self, event: Event<'_>) -> SinkResult {
        let call = event.into_owned();
        self.batch_bytes += call.array_bytes();
        self.push_call(Call::Event(call))
    }

    fn push_call(&mut self, call: Call) -> SinkResult {
        if self.failed.load(Ordering::Acquire) {
            return Err(self.join());
        }
        let batch = self.to_thread.batch();
        batch.push(call);
        if batch.len() >= BATCH || self.batch_bytes >= BATCH_BYTES {
            self.hand_over()?;
        }
        Ok(())
    }

    fn hand_over(&mut self) -> SinkResult {
        self.batch_bytes = 0;
        match self.to_thread.hand_over() {
            Ok(()) => Ok(()),
            // The thread has ended: it failed.
            Err(tortwin_handover::Gone) => Err(self.join()),
        }
    }

    /// Ends the thread and returns its error (or says it ended early).
    fn join(&mut self) -> SinkError {
        self.to_thread.close();
        match self.thread.take().map(JoinHandle::join) {
            Some(Ok(Err(e))) => e,
            Some(Err(panic)) => std::panic::resume_unwind(panic),
            _ => "the output thread ended before the run".into(),
        }
    }
}

impl Drop for SinkThread {
    fn drop(&mut self) {
        // Unfinished: the sink is dropped on its thread (its temporary files
        // removed) before the run returns.
        self.to_thread.close();
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

impl Sink for SinkThread {
    fn begin(&mut self, info: &SectionInfo<'_>) -> SinkResult {
        self.push(Event::Begin(info.clone()))
    }

    fn train(&mut self, t: &TrainEvent<'_>) -> SinkResult {
        self.push(Event::Train(t.clone()))
    }

    fn pulse(&mut self, p: &PulseEvent<'_>) -> SinkResult {
        let call = self.names.pulse(p);
        self.push_call(Call::Pulse(call))
    }

    fn measurement(&mut self, m: &MeasurementOutput) -> SinkResult {
        let call = self.names.measurement(m);
        self.push_call(Call::Measurement(call))
    }

    fn field(&mut self, f: &FieldSnapshot<'_>) -> SinkResult {
        self.push(Event::Field(f.clone()))
    }

    fn wheel_contacts(&mut self, w: &WheelContacts<'_>) -> SinkResult {
        self.push(Event::WheelContacts(w.clone()))
    }

    fn line_wheels(&mut self, w: &LineWheels<'_>) -> SinkResult {
        self.push(Event::LineWheels(w.clone()))
    }

    fn weather(&mut self, log_time_ns: u64) -> SinkResult {
        self.push(Event::Weather(log_time_ns))
    }

    fn alert(&mut self, alert: &Alert) -> SinkResult {
        self.push(Event::Alert(alert.clone()))
    }

    fn finish(&mut self, summary: &RunSummary) -> SinkResult {
        self.push(Event::Finish(summary.clone()))?;
        self.hand_over()?;
        self.to_thread.close();
        match self.thread.take().map(JoinHandle::join) {
            Some(Ok(result)) => result,
            Some(Err(panic)) => std::panic::resume_unwind(panic),
            None => Err("the output thread ended before the run".into()),
        }
    }
}

/// The thread: every call of every batch, in order, until the first error.
fn run<S: Sink>(mut sink: S, calls: &Taker<Vec<Call>>) -> SinkResult {
    let mut names = Names::<Arc<str>>::default();
    while let Some(mut batch) = calls.take() {
        for call in batch.drain(..) {
            match call {
                Call::Event(event) => event.send_to(&mut sink)?,
                Call::Pulse(p) => names.send_pulse(p, &mut sink)?,
                Call::Measurement(m) => names.send_measurement(m, &mut sink)?,
            }
        }
        calls.give_back(batch);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sink::{SnapshotKind, TrackInfo};
    use std::borrow::Cow;
    use std::sync::Mutex;
    use tortwin_recording::Applicator;
    use tortwin_recording::{Direction, Quantity, Section};

    /// Writes every call it gets as a line; fails at call `fail_at`.
    struct Log {
        lines: Arc<Mutex<Vec<String>>>,
        fail_at: Option<usize>,
        dropped: Arc<AtomicBool>,
    }

    impl Log {
        fn line(&mut self, line: String) -> SinkResult {
            let mut lines = self.lines.lock().expect("not poisoned");
            if Some(lines.len()) == self.fail_at {
                return Err(format!("disk full at call {}", lines.len()).into());
            }
            lines.push(line);
            Ok(())
        }
    }

    impl Drop for Log {
        fn drop(&mut self) {
            self.dropped.store(true, Ordering::Release);
        }
    }

    impl Sink for Log {
        fn begin(&mut self, i: &SectionInfo<'_>) -> SinkResult {
            self.line(format!("begin {} {:?}", i.section.section_id, i.grid_d_m))
        }
        fn train(&mut self, t: &TrainEvent<'_>) -> SinkResult {
            self.line(format!(
                "train {} {} {}",
                t.train_id, t.log_time_ns, t.axles
            ))
        }
        fn pulse(&mut self, p: &PulseEvent<'_>) -> SinkResult {
            self.line(format!(
                "pulse {} {} {} {} {}",
                p.applicator, p.applicator_id, p.rail, p.rail_name, p.mass_kg
            ))
        }
        fn measurement(&mut self, m: &MeasurementOutput) -> SinkResult {
            self.line(format!(
                "measurement {} {} {} {} {} {:?} {:?} {}",
                m.index_in_file,
                m.site,
                m.site_id,
                m.rail,
                m.rail_name,
                m.train_id,
                m.axle_index,
                m.simulated
            ))
        }
        fn field(&mut self, f: &FieldSnapshot<'_>) -> SinkResult {
            self.line(format!(
                "field {} {} {} {:?} {:?} {:?} {:?}",
                f.train_id, f.rail_name, f.band, f.mu, f.adhesion, f.rail_mass_kg, f.wheel_mass_kg
            ))
        }
        fn wheel_contacts(&mut self, w: &WheelContacts<'_>) -> SinkResult {
            self.line(format!("wheel {} {:?} {:?}", w.axle, w.seen_mass_kg, w.mu))
        }
        fn finish(&mut self, s: &RunSummary) -> SinkResult {
            self.line(format!("finish {}", s.trains))
        }
    }

    /// Every kind of call, `trains` trains' worth (over several batches);
    /// the pulses and measurements with names that change (another train's,
    /// another index's, and from train 350 on another text for an index
    /// already seen), and measurements without a train between those of one.
    fn drive(sink: &mut dyn Sink, trains: usize) -> SinkResult {
        let section = Section {
            section_id: "s".into(),
            length_m: 6.0,
            rails: vec!["high".into(), "low".into()],
            curve_radius_m: None,
            rail_head_radius_m: 0.3,
            nominal_wheel_diameter_m: 0.92,
            applicators: vec![Applicator {
                id: "A1".into(),
                position_m: 1.0,
                rails: vec![0, 1],
                nominal_pulse_kg: 1e-4,
            }],
            sites: vec![tortwin_recording::Site {
                id: "S1".into(),
                position_m: 3.0,
            }],
        };
        let tracks = vec![
            TrackInfo {
                rail: 0,
                rail_name: "high".into(),
                band: "top".into(),
            },
            TrackInfo {
                rail: 1,
                rail_name: "low".into(),
                band: "top".into(),
            },
        ];
        let d_m = [0.0, 2.9, 5.8];
        sink.begin(&SectionInfo {
            section: Cow::Borrowed(&section),
            grid_d_m: (&d_m[..]).into(),
            tracks: (&tracks).into(),
            applicator_points: (&[0][..]).into(),
            site_points: (&[1][..]).into(),
            origin_ns: 0,
            line: None,
        })?;
        for k in 0..trains {
            let id = format!("T{}", k / 2);
            let x = k as f64;
            sink.train(&TrainEvent {
                log_time_ns: k as u64,
                end_ns: k as u64 + 1,
                train_id: (&id).into(),
                direction: Direction::Up,
                speed_mps: 20.0,
                axles: 4,
            })?;
            let renamed = if k >= 350 { "x" } else { "" };
            sink.pulse(&PulseEvent {
                log_time_ns: k as u64,
                applicator: k % 2,
                applicator_id: format!("A{}{renamed}", k % 2 + 1).into(),
                rail: k % 2,
                rail_name: (&section.rails[k % 2]).into(),
                mass_kg: x,
            })?;
            for j in 0..3 {
                sink.measurement(&MeasurementOutput {
                    log_time_ns: k as u64,
                    index_in_file: (3 * k + j) as u64,
                    site_id: format!("S{}{renamed}", j % 2 + 1).as_str().into(),
                    site: j % 2,
                    rail_name: section.rails[j % 2].as_str().into(),
                    rail: j % 2,
                    quantity: Quantity::Mu,
                    train_id: (j < 2).then(|| id.as_str().into()),
                    axle_index: Some(j),
                    measured: 0.3,
                    simulated: 0.3 + x,
                    readout: None,
                })?;
            }
            sink.wheel_contacts(&WheelContacts {
                track: 1,
                rail: 1,
                direction: Direction::Up,
                train_seq: k,
                axle: 0,
                seen_mass_kg: vec![x, 2.0 * x, 3.0 * x].into(),
                mu: (k % 3 == 0).then(|| (&[0.1, 0.2, 0.3][..]).into()),
            })?;
            sink.field(&FieldSnapshot {
                kind: SnapshotKind::Train,
                log_time_ns: k as u64,
                train_id: (&id).into(),
                track: k % 2,
                rail_name: (&tracks[k % 2].rail_name).into(),
                band: (&tracks[k % 2].band).into(),
                wheel_pass: k as u64,
                d_m: (&d_m[..]).into(),
                mu: vec![x, 1.0, 2.0].into(),
                adhesion: vec![3.0, x, 4.0].into(),
                rail_mass_kg: vec![5.0, 6.0, x].into(),
                wheel_mass_kg: vec![7.0, 8.0, 9.0 + x].into(),
            })?;
        }
        sink.finish(&RunSummary {
            trains: trains as u64,
            ..RunSummary::default()
        })
    }

    fn log(fail_at: Option<usize>) -> (Log, Arc<Mutex<Vec<String>>>, Arc<AtomicBool>) {
        let lines = Arc::new(Mutex::new(Vec::new()));
        let dropped = Arc::new(AtomicBool::new(false));
        let sink = Log {
            lines: Arc::clone(&lines),
            fail_at,
            dropped: Arc::clone(&dropped),
        };
        (sink, lines, dropped)
    }

    #[test]
    fn the_thread_gets_the_same_calls_in_the_same_order() {
        let (mut direct, direct_lines, _) = log(None);
        drive(&mut direct, 700).expect("the direct sink takes every call");
        let (sink, threaded_lines, dropped) = log(None);
        let mut threaded = SinkThread::spawn("test", sink, true).expect("a thread");
        drive(&mut threaded, 700).expect("the threaded sink takes every call");
        assert!(dropped.load(Ordering::Acquire), "finish ends the thread");
        let (a, b) = (direct_lines.lock().unwrap(), threaded_lines.lock().unwrap());
        assert_eq!(a.len(), 1 + 700 * 7 + 1);
        assert!(*a == *b, "the calls differ");
    }

    #[test]
    fn an_error_of_the_sink_comes_back_and_the_sink_is_dropped() {
        for fail_at in [0, 1, 1500, 4901] {
            let (sink, _, dropped) = log(Some(fail_at));
            let mut threaded = SinkThread::spawn("test", sink, true).expect("a thread");
            let err = drive(&mut threaded, 700).expect_err("the sink fails");
            assert_eq!(err.to_string(), format!("disk full at call {fail_at}"));
            drop(threaded);
            assert!(dropped.load(Ordering::Acquire));
        }
        // Dropped unfinished (the engine failed): the sink is gone too.
        let (sink, lines, dropped) = log(None);
        let mut threaded = SinkThread::spawn("test", sink, true).expect("a thread");
        threaded
            .train(&TrainEvent {
                log_time_ns: 0,
                end_ns: 1,
                train_id: "T".into(),
                direction: Direction::Down,
                speed_mps: 1.0,
                axles: 1,
            })
            .expect("one call");
        drop(threaded);
        assert!(dropped.load(Ordering::Acquire));
        // What was not handed over is not delivered: the run failed anyway.
        assert!(lines.lock().unwrap().len() <= 1);
    }
}
