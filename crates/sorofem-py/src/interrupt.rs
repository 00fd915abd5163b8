//! Long calls into the core (static solves, time integration) that Ctrl-C stops within one
//! Newton iteration.
//!
//! Python runs signal handlers only in the main thread, and `PyErr_CheckSignals` does nothing
//! anywhere else, while the core's Newton loop runs on a worker of the thread pool. So the call
//! goes to the pool, and the main thread waits for it, asking Python for pending signals every
//! [`SIGNAL_POLL`]; a handler that raises (SIGINT's `KeyboardInterrupt`, the command line's
//! SIGTERM) sets the call's [`Interrupt`], which the core polls once per Newton iteration.

use crate::errors::{from_panic, to_py, IntoPyResult};
use pyo3::exceptions::PyKeyboardInterrupt;
use pyo3::prelude::*;
use sorofem_core::newton::Interrupt;
use sorofem_core::{Error, SolveReport};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::mpsc::{channel, RecvTimeoutError};
use std::time::Duration;

/// How often the waiting main thread runs Python's signal handlers: the delay it adds to a
/// Ctrl-C before the core sees it (a GIL acquisition each time, microseconds).
const SIGNAL_POLL: Duration = Duration::from_millis(20);

/// [`crate::errors::guarded`] for a call that takes the [`Interrupt`] it must poll: a signal
/// handler that raises while the call runs stops it, and its exception is raised, as
/// `sorofem.errors.Interrupted` (with the core's report so far in `.report` and the handler's
/// `.signal`) when it was a `KeyboardInterrupt`. Outside the main thread (where Python never
/// runs handlers) it is `guarded` with an interrupt nobody requests.
pub fn interruptible<T: Send>(
    py: Python<'_>,
    call: impl FnOnce(Interrupt) -> Result<T, Error> + Send,
) -> PyResult<T> {
    if !on_main_thread(py)? {
        return crate::errors::guarded(py, || call(Interrupt::default()));
    }
    let interrupt = Interrupt::new();
    let (outcome, raised) = py.detach(|| {
        let (done, finished) = channel();
        let requested = interrupt.clone();
        rayon::in_place_scope(|scope| {
            scope.spawn(move |_| {
                // The receiver waits for this: the send cannot fail.
                let _ = done.send(catch_unwind(AssertUnwindSafe(|| call(requested))));
            });
            let mut raised: Option<PyErr> = None;
            loop {
                match finished.recv_timeout(SIGNAL_POLL) {
                    Ok(outcome) => return (Some(outcome), raised),
                    Err(RecvTimeoutError::Timeout) if raised.is_none() => {
                        if let Err(error) = Python::attach(|py| py.check_signals()) {
                            raised = Some(error);
                            interrupt.request();
                        }
                    }
                    Err(RecvTimeoutError::Timeout) => {}
                    // Unreachable (the job sends, even after a panic); the scope's end waits.
                    Err(RecvTimeoutError::Disconnected) => return (None, raised),
                }
            }
        })
    });
    match (outcome, raised) {
        // Raised even when the call has finished: the handler ran, and a Ctrl-C is never lost.
        (outcome, Some(raised)) => {
            let report = match outcome {
                Some(Ok(Err(Error::Interrupted { report }))) => Some(report),
                _ => None,
            };
            Err(as_interrupted(py, raised, report))
        }
        (Some(Ok(result)), None) => result.py(py),
        (Some(Err(payload)), None) => Err(from_panic(py, payload)),
        (None, None) => Err(from_panic(py, Box::new("the call ended without a result"))),
    }
}

fn on_main_thread(py: Python<'_>) -> PyResult<bool> {
    let threading = py.import("threading")?;
    let current = threading.call_method0("current_thread")?;
    let main = threading.call_method0("main_thread")?;
    Ok(current.is(&main))
}

/// The exception a signal handler raised during the call: a `KeyboardInterrupt` becomes
/// `sorofem.errors.Interrupted` saying how far the solve got (`report`: the core's, when it
/// stopped before finishing); anything else is raised as it is.
fn as_interrupted(py: Python<'_>, raised: PyErr, report: Option<Box<SolveReport>>) -> PyErr {
    if !raised.is_instance_of::<PyKeyboardInterrupt>(py) {
        return raised;
    }
    let signal = raised
        .value(py)
        .getattr("signal")
        .and_then(|s| s.extract::<String>())
        .unwrap_or_else(|_| "SIGINT".into());
    let build = || -> PyResult<PyErr> {
        let exception = match report {
            Some(report) => to_py(py, Error::Interrupted { report }),
            None => PyErr::from_value(
                py.import("sorofem.errors")?
                    .getattr("Interrupted")?
                    .call1(("interrupted",))?,
            ),
        };
        exception.value(py).setattr("signal", signal)?;
        Ok(exception)
    };
    build().unwrap_or_else(|e| e)
}
