//! SIGINT (Ctrl-C), SIGTERM and SIGHUP: one handler for the whole life of a command (the `ctrlc`
//! crate with its `termination` feature).
//!
//! Before training starts (flag checks, loading, initialisation) nothing of value exists yet: a
//! signal ends the process at once (status 130), having written nothing but the empty output
//! folder. Once the trainer exists ([`Signals::arm`]), a signal raises the run's
//! [`StopSignal`]: [`bbsplat::train::run`] checks it before every step and between the views of
//! an evaluation, then writes its checkpoint (an atomic write in progress is finished first) and
//! stops. A second signal while the first is being handled ends the process at once; the atomic
//! writes leave either the previous file or the new one.

use anyhow::{Context, Result};
use bbsplat::train::StopSignal;
use std::sync::Arc;
use std::sync::atomic::{AtomicU8, Ordering};

const LOADING: u8 = 0;
const TRAINING: u8 = 1;
const STOPPING: u8 = 2;

/// The installed handler's state.
#[derive(Clone)]
pub struct Signals {
    phase: Arc<AtomicU8>,
    stop: StopSignal,
}

impl Signals {
    /// Installs the handler (once per process); until [`Signals::arm`] a signal exits at once.
    pub fn install() -> Result<Self> {
        let signals = Signals {
            phase: Arc::new(AtomicU8::new(LOADING)),
            stop: StopSignal::new(),
        };
        let handler = signals.clone();
        ctrlc::set_handler(move || handler.on_signal()).context("installing the signal handler")?;
        Ok(signals)
    }

    fn on_signal(&self) {
        match self.phase.swap(STOPPING, Ordering::SeqCst) {
            LOADING => {
                eprintln!("interrupted before training started; no run was written");
                std::process::exit(130);
            }
            TRAINING => self.stop.request(),
            _ => {
                eprintln!("interrupted again: exiting now (the files on disk are each complete)");
                std::process::exit(130);
            }
        }
    }

    /// From now on a signal stops the run with a checkpoint; returns the run's stop signal. A
    /// signal that arrived before is kept as a stop request.
    pub fn arm(&self) -> StopSignal {
        if self
            .phase
            .compare_exchange(LOADING, TRAINING, Ordering::SeqCst, Ordering::SeqCst)
            .is_err()
        {
            self.stop.request();
        }
        self.stop.clone()
    }
}
