//! The MCAP writer on a thread of its own: the engine's thread serializes
//! each message and hands it over; chunk compression (zstd at a high level,
//! about a second per month of traffic) runs beside the engine instead of
//! after every chunk's worth of it. The buffers travel back for reuse, so
//! the steady state allocates nothing.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};
use std::thread::JoinHandle;

use super::McapError;

pub(super) type Writer = mcap::Writer<BufWriter<File>>;

/// Messages in flight between the threads: a few chunks' worth at most.
const QUEUE: usize = 64;

/// A message for the writer thread.
struct Job {
    header: mcap::records::MessageHeader,
    data: Vec<u8>,
    topic: &'static str,
}

/// The sending end; the writer comes back from [`WriterThread::close`].
pub(super) struct WriterThread {
    jobs: Option<SyncSender<Job>>,
    spare: Receiver<Vec<u8>>,
    thread: Option<JoinHandle<Result<Writer, McapError>>>,
    path: PathBuf,
}

impl WriterThread {
    /// Starts the thread that writes to `writer`; `path` names the output in errors.
    pub(super) fn start(writer: Writer, path: &Path) -> Result<WriterThread, McapError> {
        let (jobs, incoming) = sync_channel::<Job>(QUEUE);
        let (give_back, spare) = sync_channel::<Vec<u8>>(QUEUE);
        let thread_path = path.to_path_buf();
        let thread = std::thread::Builder::new()
            .name("tortwin-mcap".to_owned())
            .spawn(move || {
                let mut writer = writer;
                for job in incoming {
                    writer
                        .write_to_known_channel(&job.header, &job.data)
                        .map_err(|source| McapError::Mcap {
                            path: thread_path.clone(),
                            what: format!("writing {}", job.topic),
                            source,
                        })?;
                    // The engine's side may have stopped taking them back.
                    let _ = give_back.try_send(job.data);
                }
                Ok(writer)
            })
            .map_err(|source| McapError::Io {
                path: path.to_path_buf(),
                what: "starting the writer thread",
                source,
            })?;
        Ok(WriterThread {
            jobs: Some(jobs),
            spare,
            thread: Some(thread),
            path: path.to_path_buf(),
        })
    }

    /// A cleared buffer to serialize the next message into.
    pub(super) fn buffer(&self) -> Vec<u8> {
        let mut buffer = self.spare.try_recv().unwrap_or_default();
        buffer.clear();
        buffer
    }

    /// Hands a serialized message to the writer thread. If that thread has
    /// stopped, its error.
    pub(super) fn send(
        &mut self,
        header: mcap::records::MessageHeader,
        data: Vec<u8>,
        topic: &'static str,
    ) -> Result<(), McapError> {
        let sent = match &self.jobs {
            Some(jobs) => jobs.send(Job {
                header,
                data,
                topic,
            }),
            None => {
                return Err(McapError::Finished {
                    path: self.path.clone(),
                })
            }
        };
        match sent {
            Ok(()) => Ok(()),
            // The thread stopped on an error: that error.
            Err(_) => match self.close() {
                Err(e) => Err(e),
                Ok(_) => Err(McapError::Finished {
                    path: self.path.clone(),
                }),
            },
        }
    }

    /// Waits for the thread to write everything sent; the writer, or the
    /// thread's error.
    pub(super) fn close(&mut self) -> Result<Writer, McapError> {
        drop(self.jobs.take());
        let Some(thread) = self.thread.take() else {
            return Err(McapError::Finished {
                path: self.path.clone(),
            });
        };
        match thread.join() {
            Ok(result) => result,
            Err(_) => Err(McapError::Io {
                path: self.path.clone(),
                what: "writing (the writer thread panicked)",
                source: std::io::Error::other("writer thread panicked"),
            }),
        }
    }
}

impl Drop for WriterThread {
    fn drop(&mut self) {
        // Stop and join the thread: its writer (and file) closes before the
        // temporary file is deleted.
        let _ = self.close();
    }
}
