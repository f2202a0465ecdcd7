//! How far a run file can be trusted before a command reads it: whole, a `.partial` (damaged
//! or not), cut short, or unusable; and what each command does about it.

use crate::error::{CliError, Result};
use std::path::Path;

/// What a run file's structure lets verify, resume, info, plot, snapshot, profile and export do with it
/// (see `record::read`: the reader that checks it is the one they read with).
pub enum FileState {
    /// Finished and whole, or a `.partial` that ends as a killed run leaves it (on a record
    /// boundary or in a chunk cut short).
    Usable,
    /// A `.partial` damaged before its end: it is read up to its last intact chunk. The text
    /// says where and what is lost.
    PartialDamaged(String),
    /// Named as finished (not `.partial`) but without the footer and end magic a finished run
    /// writes: cut short or damaged after it was written.
    Incomplete(String),
    /// Cannot be read as a run: not a run file, missing, or finished but damaged.
    Unusable(String),
}

pub fn file_state(path: &Path) -> FileState {
    let check = match mps_runner::record::check_run(path) {
        Ok(c) => c,
        Err(e) => return FileState::Unusable(e.to_string()),
    };
    if check.complete {
        return FileState::Usable;
    }
    let n = check.checkpoints;
    if !is_partial(path) {
        let held = match &check.stop {
            Some(stop) => format!("{stop} ({n} checkpoints before it)"),
            None => format!("it ends on a record boundary after {n} checkpoints"),
        };
        return FileState::Incomplete(format!(
            "{} is incomplete: it does not end with the MCAP footer and magic that a finished run writes (cut short or damaged after it was written; a run in progress or killed is named .partial); {held}",
            path.display()
        ));
    }
    match check.stop.filter(|s| s.damaged) {
        Some(stop) => FileState::PartialDamaged(format!(
            "{} is damaged: {stop}; it is read up to the last intact chunk before that ({n} checkpoints), and no further",
            path.display()
        )),
        None => FileState::Usable,
    }
}

fn is_partial(path: &Path) -> bool {
    path.to_string_lossy().ends_with(".partial")
}

/// For verify and info: an unusable file is refused (exit 2); a damaged `.partial` is read
/// with a warning; a file named finished without its end gives why (Some), to be reported.
pub fn incomplete_or_refused(file: &Path) -> Result<Option<String>> {
    match file_state(file) {
        FileState::Unusable(why) => Err(CliError::BadInput(why)),
        FileState::Incomplete(why) => Ok(Some(why)),
        FileState::PartialDamaged(why) => {
            eprintln!("warning: {why}");
            Ok(None)
        }
        FileState::Usable => Ok(None),
    }
}

/// For the commands that present a file's contents (plot, snapshot, profile, export): an incomplete
/// or damaged finished file is refused (exit 2) rather than drawn from part of it; a
/// `.partial` file is drawn with a warning (and another where it is damaged).
pub fn readable_run(path: &Path) -> Result<()> {
    match file_state(path) {
        FileState::Incomplete(why) | FileState::Unusable(why) => {
            return Err(CliError::BadInput(why));
        }
        FileState::PartialDamaged(why) => eprintln!("warning: {why}"),
        FileState::Usable => {}
    }
    if is_partial(path) {
        eprintln!(
            "warning: {} is an unfinished run (in progress or killed): this shows what it holds so far",
            path.display()
        );
    }
    Ok(())
}
