//! SIGINT and SIGTERM for the commands that run simulations (run, sweep, resume, bench,
//! calibrate): the first stops the run cleanly, a second exits at once.

use crate::error::EXIT_INTERRUPTED;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// SIGINT and SIGTERM set the returned flag: the run stops at the next step and finishes its
/// file as interrupted (resumable). A second signal exits at once (the `.partial` file keeps
/// every checkpoint written and can be resumed too).
pub fn flag() -> Option<Arc<AtomicBool>> {
    let flag = Arc::new(AtomicBool::new(false));
    let handler_flag = flag.clone();
    let installed = ctrlc::set_handler(move || {
        if handler_flag.swap(true, Ordering::SeqCst) {
            eprintln!("second interrupt: exiting now; the .partial file can be resumed");
            std::process::exit(i32::from(EXIT_INTERRUPTED));
        }
        eprintln!("interrupt: stopping after this step and finishing the file");
    });
    match installed {
        Ok(()) => Some(flag),
        Err(e) => {
            eprintln!("warning: cannot install the signal handler: {e}");
            None
        }
    }
}
