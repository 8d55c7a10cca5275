//! Tests' view of the log: the lines written on this thread while a
//! [`Capture`] lives.

use std::io::Write;
use std::sync::{Arc, Mutex, PoisonError};

use tracing::subscriber::DefaultGuard;

#[derive(Clone, Default)]
struct Sink(Arc<Mutex<Vec<u8>>>);

impl Write for Sink {
    fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
        self.0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .extend_from_slice(b);
        Ok(b.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// The log of this thread, captured until dropped.
pub struct Capture {
    sink: Sink,
    _guard: DefaultGuard,
    _second: tracing::Dispatch,
}

impl Capture {
    /// Capture this thread's log lines (every level from DEBUG up is not
    /// needed: INFO and above, as the gateway logs by default).
    pub fn start() -> Capture {
        let sink = Sink::default();
        let writer = sink.clone();
        let subscriber = tracing_subscriber::fmt()
            .with_writer(move || writer.clone())
            .with_ansi(false)
            .finish();
        let guard = tracing::subscriber::set_default(subscriber);
        // A second live dispatcher: with one, tracing decides whether a
        // log line is wanted from the first thread that reaches it
        // (another test's, with no subscriber: never); with two, from
        // every dispatcher.
        let second = tracing::Dispatch::new(tracing_subscriber::registry());
        Capture {
            sink,
            _guard: guard,
            _second: second,
        }
    }

    /// The lines so far.
    pub fn lines(&self) -> Vec<String> {
        let bytes = self
            .sink
            .0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone();
        String::from_utf8_lossy(&bytes)
            .lines()
            .map(str::to_string)
            .collect()
    }
}
